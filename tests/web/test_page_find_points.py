"""The page's "Find points": the real worker's search places P1...P7 on a rendered photo (checked
against the renderer's projection of the box's corners); as found, the scan goes as points "auto"
and its results say so; with a point dragged, as the points shown; a photo with no box gets the
search's reason in words.
Small renders (640x512): the search and the scan stay cheap."""

from __future__ import annotations

import re

import cv2
import httpx
import numpy as np
from page_driver import KEY, NO_SCALE, PageDriver, save_photo
from playwright.sync_api import expect

from prismcore.locate.search import find_points
from prismsynth.scenes import clutter_scene, empty_scene

SIZE = (640, 512)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
WAIT_MS = 120_000  # the worker may be busy with another test file's job first


def test_found_points_are_placed_checked_dragged_and_measured(page, stack, tmp_path):
    scene = clutter_scene(0, image_size=SIZE)
    d = PageDriver(page)
    d.log_in()
    d.add_photos(save_photo(scene, tmp_path / "scene.png"))
    page.get_by_role("button", name="Find points").click()
    status = page.locator("#find-status")
    expect(status).to_contain_text("Found the box", timeout=WAIT_MS)
    marks = {n: d.mark(n) for n in NAMES}
    hit = set()
    for name, xy in marks.items():
        assert xy is not None, name
        dist = np.linalg.norm(scene.vertices_px - np.asarray(xy), axis=1)
        assert dist.min() <= 3.0, (name, xy, dist.min())
        hit.add(int(np.argmin(dist)))
    assert len(hit) == 6  # P4 is P1 or P2; the other six are six corners
    expect(page.get_by_label("Also mark P6 and P7")).to_be_checked()
    face = page.get_by_label("Second face", exact=True).input_value()
    assert face in ("right", "left", "top") and f"second face: {face}" in status.text_content()
    expect(page.locator("#next-point")).to_contain_text("Every point is placed")

    # As found, the scan goes as points "auto": the worker finds the same points again, and the
    # results say so. In pixels, chosen (the page has no default scale).
    page.get_by_label("Scale", exact=True).select_option(label=NO_SCALE)
    page.get_by_role("button", name="Add this scan to the batch").click()
    expect(page.locator("#batch")).to_contain_text("scene.png (points found)")
    expect(page.get_by_label("P1 x (pixels)")).to_have_value("")  # a scan added: points cleared
    page.get_by_role("button", name="Find points").click()  # again: the stored answer
    expect(page.get_by_label("P1 x (pixels)")).not_to_have_value("", timeout=WAIT_MS)
    assert {n: d.mark(n) for n in NAMES} == marks
    p3 = marks["p3"]
    d.drag(p3, (p3[0] + 3, p3[1] + 2))  # the person corrects a point: the points go as they are
    moved = d.mark("p3")
    assert np.allclose(moved, (p3[0] + 3, p3[1] + 2), atol=1.0), (moved, p3)
    page.get_by_role("button", name="Add this scan to the batch").click()
    expect(page.locator("#batch")).to_contain_text("scene.png (points found, then adjusted)")
    ended = d.submit_and_wait(timeout_ms=WAIT_MS)
    assert re.search(r"Done", ended), (ended, page.locator("#form-error").text_content())
    expect(page.locator("#details dd[data-field=reference-points]")).to_contain_text(
        re.compile(r"found automatically \(confidence 0\.\d\d\)"))
    job_id = re.search(r"Job ([0-9a-f]{8})", ended).group(1)
    jobs = httpx.get(f"{stack.url}/v1/jobs", headers={"X-API-Key": KEY}).json()["jobs"]
    job = next(j for j in jobs if j["id"].startswith(job_id))
    auto, clicked = (i["result"] for i in job["items"])
    assert (auto["points_source"], clicked["points_source"]) == ("auto", "clicked")
    for name, xy in marks.items():  # the job's search found what the page's did
        assert np.allclose(auto["reference_points"][name], xy, atol=0.1), (name, auto["reference_points"])
    assert np.allclose(clicked["reference_points"]["p3"], moved, atol=0.1)
    assert all(v > 0 for v in d.dimensions().values())


def test_a_photo_without_a_box_says_why_and_places_nothing(page, tmp_path):
    empty = empty_scene(0, image_size=SIZE)
    d = PageDriver(page)
    d.log_in()
    path = tmp_path / "empty.png"
    assert cv2.imwrite(str(path), cv2.cvtColor(empty, cv2.COLOR_RGB2BGR))
    d.add_photos(path)
    page.get_by_role("button", name="Find points").click()
    status = page.locator("#find-status")
    expect(status).to_contain_text("No points placed.", timeout=WAIT_MS)
    reason = find_points(empty).reason  # the engine's own words, passed on
    assert reason and reason[1:] in status.text_content(), (reason, status.text_content())
    expect(status).to_contain_text("Click P1 on the box you want")
    assert all(d.mark(n) is None for n in NAMES[:5])  # P6 and P7 are not asked for


def test_a_second_face_the_person_changed_counts_as_adjusted(page, tmp_path):
    # The points as found but another second face chosen: the scan must not go as "auto" (the
    # worker's search would put its own face back), but as the person set it.
    scene = clutter_scene(0, image_size=SIZE)
    d = PageDriver(page)
    d.log_in()
    d.add_photos(save_photo(scene, tmp_path / "scene.png"))
    page.get_by_role("button", name="Find points").click()
    expect(page.locator("#find-status")).to_contain_text("Found the box", timeout=WAIT_MS)
    select = page.get_by_label("Second face", exact=True)
    found = select.input_value()
    select.select_option(next(f for f in ("right", "left", "top") if f != found))
    page.get_by_label("Scale", exact=True).select_option(label=NO_SCALE)
    page.get_by_role("button", name="Add this scan to the batch").click()
    expect(page.locator("#batch")).to_contain_text("scene.png (points found, then adjusted)")

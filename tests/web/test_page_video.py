"""A video through the page: an MJPEG AVI (which no browser plays) uploaded, a frame picked and
shown as the worker decodes it, the points clicked on that frame, the frames chosen, the job run
by the real worker, and the summary, the per-frame list and a frame's cloud in 3D checked."""

from __future__ import annotations

import json
import re
from pathlib import Path

import httpx
import numpy as np
import pytest
from page_driver import KEY, PageDriver
from playwright.sync_api import expect

from prismcore.spec import ScanSpec
from prismsynth import Box, render_clip, write_video

BOX = Box(120.0, 80.0, 60.0)
FRAMES = 8
ORDER = ("p1", "p2", "p3", "p2", "p5", "p6", "p7")  # P4 is the corner P2 marks: a click on P2
TOLERANCE = 0.02


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> tuple[list, Path]:
    scenes = render_clip(BOX, FRAMES, seed=3)
    path = tmp_path_factory.mktemp("clip") / "clip.avi"
    write_video((s.image for s in scenes), path, codec="MJPG")
    return scenes, path


def _add_video(page, path: Path) -> None:
    page.get_by_label("Add photos or a video").set_input_files(str(path))
    listed = page.locator("#photo-list")
    expect(listed).to_contain_text(f"{path.name} (video): uploaded, {FRAMES} frames at 25 fps")
    size = "640 \u00d7 512"  # the page's multiplication sign
    info = f"{path.name}: {FRAMES} frames at 25 fps, {size}, codec MJPG."
    expect(page.locator("#video-info")).to_have_text(info)
    expect(page.locator("#frame-status")).to_have_text(f"Showing frame 0 of {FRAMES} (0.000 s).")


def _pick_frame(page, n: int, *, seen: bool = False) -> None:
    """Type frame `n` in; unless `seen` before (the page keeps it), it comes from the API."""
    field = page.get_by_label("Frame number")
    if seen:
        field.fill(str(n))
        field.press("Enter")
    else:
        with page.expect_response(re.compile(rf"/v1/uploads/\w+/frames/{n}\.png$")) as got:
            field.fill(str(n))
            field.press("Enter")
        assert got.value.status in (200, 202)
    expect(page.locator("#frame-status")).to_have_text(f"Showing frame {n} of {FRAMES} ({n / 25:.3f} s).")


def _scale(page, scene) -> None:
    page.get_by_label("Scale", exact=True).select_option(label="Shooting distance and focal length")
    page.get_by_label("Shooting distance to the front face (mm)").fill(str(scene.distance_mm))
    page.get_by_label("Focal length", exact=False).fill(str(scene.focal_px))


def _submit(page, d: PageDriver) -> dict:
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        assert "Done" in d.submit_and_wait(), page.locator("#form-error").text_content()
    return json.loads(sent.value.post_data)["items"][0]


def test_a_frame_marked_then_every_second_frame_measured(page, stack, clip):
    scenes, path = clip
    d = PageDriver(page)
    d.log_in()
    _add_video(page, path)
    _pick_frame(page, 3)
    page.get_by_label("Also mark P6 and P7").check()
    for name in ORDER:
        d.click_photo(scenes[3].points[name])
    expect(page.locator("#next-point")).to_contain_text("Every point is placed")
    for name in ("p1", "p2", "p3", "p5", "p6", "p7"):  # on frame 3's corners, as clicked
        assert np.allclose(d.mark(name), scenes[3].points[name], atol=1 / d.view()[0] + 0.05), name
    expect(page.locator("#marked-frames")).to_have_text(
        "The points were marked on frame 3; they apply to every frame measured.")
    _scale(page, scenes[3])
    page.get_by_label("Frames to measure").select_option(label="Every Nth frame, and the marked frame")
    page.get_by_label("Every Nth frame: N").fill("2")
    expect(page.locator("#selection-note")).to_have_text("Measures 5 frames: 0, 2, 3, 4, 6.")

    item = _submit(page, d)
    spec = ScanSpec.model_validate(item)  # what the page sent is a valid job item
    assert spec.frames.indices == [0, 2, 3, 4, 6] and spec.frame_points is None
    assert spec.points.p1 == pytest.approx(tuple(d.mark("p1")))
    expect(page.locator("#job-percent")).to_have_text("100 % · 5 frames measured")

    job = httpx.get(f"{stack.url}/v1/jobs?limit=1", headers={"X-API-Key": KEY}).json()["jobs"][0]
    summary = job["items"][0]["result"]["summary"]
    for dim, true in (("width", BOX.width_mm), ("height", BOX.height_mm), ("depth", BOX.depth_mm)):
        cell = page.locator(f"#video-summary tr[data-dimension={dim}] td[data-stat=median]")
        expect(cell).to_have_text(f"{summary['dimensions'][dim]['median']:.2f}")
        assert abs(float(cell.text_content()) / true - 1) < TOLERANCE, (dim, cell.text_content())
    rows = page.locator("#frame-results tbody tr")
    expect(rows).to_have_count(5)
    assert [rows.nth(i).get_attribute("data-frame") for i in range(5)] == ["0", "2", "3", "4", "6"]
    expect(page.locator("#frame-results tbody tr", has_text="succeeded")).to_have_count(5)
    # Per frame: the service's default outputs (CSV and PLY) and the report.
    expect(page.locator("#frame-results a")).to_have_text(["CSV", "PLY", "Report"] * 5)
    expect(page.get_by_role("link", name="Download the summary (JSON)")).to_be_visible()

    page.get_by_label("Frame in the 3D view").select_option(label="Frame 3")
    expect(page.locator("#viewer-status")).to_contain_text("of frame 3", timeout=30_000)
    pixels = d.viewer_pixels()
    colours = np.unique(pixels.reshape(-1, 3), axis=0)
    assert len(colours) > 50 and pixels.std() > 5, (len(colours), pixels.std())


def test_each_marked_frame_with_its_own_points(page, stack, clip):
    scenes, path = clip
    d = PageDriver(page)
    d.log_in()
    _add_video(page, path)
    page.get_by_label("Only the frames I mark").check()
    page.get_by_label("Also mark P6 and P7").check()
    for frame in (1, 6):
        _pick_frame(page, frame)
        for name in ORDER:
            d.click_photo(scenes[frame].points[name])
    expect(page.locator("#marked-frames")).to_have_text("Marked frames: 1, 6.")
    _pick_frame(page, 1, seen=True)  # back: frame 1 still has its own points
    assert np.allclose(d.mark("p5"), scenes[1].points["p5"], atol=1 / d.view()[0] + 0.05)
    _scale(page, scenes[0])
    item = _submit(page, d)
    assert sorted(item["frame_points"]) == ["1", "6"] and "points" not in item and "frames" not in item
    for frame in (1, 6):
        assert np.allclose(item["frame_points"][str(frame)]["p7"], scenes[frame].points["p7"], atol=1)
    expect(page.locator("#frame-results tbody tr", has_text="succeeded")).to_have_count(2)


def test_a_file_that_only_looks_like_a_video(page, stack, tmp_path):
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"RIFF\x10\x00\x00\x00AVI junk" * 50)
    PageDriver(page).log_in()
    page.get_by_label("Add photos or a video").set_input_files(str(junk))
    expect(page.locator("#photo-list li.error")).to_have_text(
        "junk.avi (video): not a video the service can measure: 'junk.avi' is a truncated or corrupt "
        "AVI video: it does not open.", timeout=30_000)
    expect(page.locator("#frame-picker")).to_be_hidden()

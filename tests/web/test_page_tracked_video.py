"""A hand-held video through the page, its points marked on ONE frame and tracked by the service:
a rendered moving-camera clip (an MJPEG AVI) uploaded, a frame picked with the slider's number,
the seven points clicked on it, "tracked to the others" chosen, the job run by the real worker;
then the track on the result's scrubber: each frame drawn with its tracked points (checked
against the renderer's corners and on the canvas's pixels), the frame after a cut to another
scene marked as left out, with its reason."""

from __future__ import annotations

import functools
import json
import re
import tempfile
from pathlib import Path

import httpx
import numpy as np
import pytest
from page_driver import KEY, PageDriver
from playwright.sync_api import expect

from prismcore.spec import ScanSpec
from prismsynth import Box
from prismsynth.video import moving_clip, write_video

BOX = Box(120.0, 80.0, 60.0)
TRACKED, CUT = 16, 4  # frames of the moving camera, then a cut to a dark scene
FRAMES = TRACKED + CUT
MARKED = 8
SELECTED = [0, 4, MARKED, 12, 15, 17]  # 17: after the cut
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
ORDER = (0, 1, 2, 1, 4, 5, 6)  # P4 is the corner P2 marks (a right side): a click on P2
POINT_PX = 2.5  # tracked against the renderer's corners (clicks on screen pixels, MJPEG frames)
YELLOW = np.array([255, 212, 0])  # track-view.ts's POINT_COLOUR


@functools.cache
def _clip() -> tuple[Path, tuple[np.ndarray, ...]]:
    images, truth = moving_clip(BOX, TRACKED, image_size=(640, 360), focal_px=600.0, sway_deg=8.0, seed=0)
    rng = np.random.default_rng(0)
    dark = [rng.integers(0, 60, images[0].shape, dtype=np.uint8) for _ in range(CUT)]
    path = Path(tempfile.mkdtemp(prefix="tracked-page-")) / "handheld.avi"
    write_video([*images, *dark], path, codec="MJPG")
    return path, tuple(truth)


def _pick_frame(page, n: int) -> None:
    field = page.get_by_label("Frame number")
    with page.expect_response(re.compile(rf"/v1/uploads/\w+/frames/{n}\.png$")):
        field.fill(str(n))
        field.press("Enter")
    expect(page.locator("#frame-status")).to_have_text(f"Showing frame {n} of {FRAMES} ({n / 25:.3f} s).")


def _canvas_pixel(page, xy: np.ndarray) -> np.ndarray:
    """The track canvas's RGB at image point `xy` (px of the frame)."""
    return np.array(page.evaluate("""([x, y]) => {
        const c = document.getElementById("track-canvas");
        const s = Number(c.dataset.scale);
        const px = c.getContext("2d").getImageData(Math.round(x * s), Math.round(y * s), 1, 1).data;
        return Array.from(px.slice(0, 3));
    }""", [float(xy[0]), float(xy[1])]))


@pytest.mark.parametrize("joint", [False, True], ids=["frame-by-frame", "one-box"])
def test_points_marked_on_one_frame_are_tracked_and_shown_on_a_scrubber(page, stack, joint: bool) -> None:
    path, truth = _clip()
    d = PageDriver(page)
    d.log_in()
    page.get_by_label("Add photos or a video").set_input_files(str(path))
    expect(page.locator("#photo-list")).to_contain_text(f"{path.name} (video): uploaded, {FRAMES} frames")
    _pick_frame(page, MARKED)
    page.get_by_label("Also mark P6 and P7").check()
    for k in ORDER:
        d.click_photo(tuple(truth[MARKED][k]))
    expect(page.locator("#next-point")).to_contain_text("Every point is placed")
    page.get_by_label("The points of the frame I mark, tracked to the others").check()
    expect(page.locator("#marked-frames")).to_have_text(
        f"The points were marked on frame {MARKED}; the service tracks them to the other frames measured.")
    page.get_by_label("Scale", exact=True).select_option(label="One known edge")
    page.get_by_label("Its length (mm)").fill("120")
    page.get_by_label("Focal length", exact=False).fill("600")
    page.get_by_label("Frames to measure").select_option(label="These frames")
    page.get_by_label("Frame indices to measure").fill(", ".join(map(str, SELECTED)))
    expect(page.locator("#selection-note")).to_contain_text(
        f"The points of frame {MARKED} are tracked to each")
    if joint:
        page.get_by_label("Measure the tracked frames as one box").check()

    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        assert "Done" in d.submit_and_wait(240_000), page.locator("#form-error").text_content()
    spec = ScanSpec.model_validate(json.loads(sent.value.post_data)["items"][0])
    assert spec.points_frame == MARKED and spec.frames.indices == SELECTED
    assert spec.fit == ("joint" if joint else None)
    clicked = np.array([spec.points.as_dict()[n] for n in NAMES])
    assert np.linalg.norm(clicked - truth[MARKED], axis=1).max() < 1.5

    job = httpx.get(f"{stack.url}/v1/jobs?limit=1", headers={"X-API-Key": KEY}).json()["jobs"][0]
    item = job["items"][0]
    assert item["state"] == "succeeded", item["error"]
    track = httpx.get(f"{stack.url}/v1/jobs/{job['id']}/items/0/tracked_points.json",
                      headers={"X-API-Key": KEY}).json()
    reason = track["17"]["reason"]
    assert "cut" in reason

    # The scrubber: one button per frame selected, the one after the cut marked and listed with its reason.
    view = page.locator("#track-view")
    expect(view.locator("h3")).to_have_text(f"Points tracked from frame {MARKED}")
    strip = page.locator("#track-strip button")
    expect(strip).to_have_text([str(f) for f in SELECTED])
    expect(page.locator("#track-strip button.left-out")).to_have_text(["17"])
    expect(page.locator("#track-left-out li")).to_have_text([f"Frame 17: {reason}"])
    for frame in (0, 12, 15):
        page.locator(f"#track-strip button[data-frame='{frame}']").click()
        expect(page.locator("#track-canvas")).to_have_attribute("data-shown", str(frame))
        expect(page.locator("#track-status")).to_contain_text(f"Frame {frame}: tracked (confidence")
        points = np.array(track[str(frame)]["points"])
        assert np.linalg.norm(points - truth[frame], axis=1).max() < POINT_PX, frame
        for k in (0, 2, 4, 6):  # each drawn where the track has it
            assert np.abs(_canvas_pixel(page, points[k]) - YELLOW).max() < 40, (frame, k)
    slider = page.get_by_label("Tracked frame", exact=True)
    slider.fill(str(SELECTED.index(17)))  # the slider itself walks to the frame left out
    expect(page.locator("#track-canvas")).to_have_attribute("data-shown", "17")
    expect(page.locator("#track-status")).to_have_text(f"Frame 17 was left out: {reason}.")

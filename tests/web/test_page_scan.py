"""A scan from start to end through the page: photos in, points clicked on them, the job run by the
real worker, its dimensions checked against the synthetic box's true size, the cloud drawn in 3D."""

from __future__ import annotations

import json
import math
import re

import httpx
import numpy as np
import pytest
from page_driver import KEY, PageDriver, save_photo
from playwright.sync_api import expect

from prism_worker.artifacts import OVERLAY_MAX_SIDE
from prismcore.spec import ScanSpec
from prismsynth import Box, render_front_view, render_oblique_view, render_side_view

BOX = Box(120.0, 80.0, 60.0)
CYAN, ORANGE = (0, 200, 255), (255, 140, 0)  # the front's and the side's outlines (marker-draw.ts)
TOLERANCE = 0.02  # clicks land within about a screen pixel: ~1 image pixel at the fitted zoom


def _close(got: dict[str, float], box: Box) -> None:
    want = {"width": box.width_mm, "height": box.height_mm, "depth": box.depth_mm}
    for k, v in want.items():
        assert abs(got[k] / v - 1) < TOLERANCE, (k, got, want)


def test_one_oblique_photo_with_perspective(page, stack, tmp_path):
    scene = render_oblique_view(BOX, seed=3)
    truth = {n: scene.points[n] for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")}
    d = PageDriver(page)
    d.log_in()
    d.add_photos(save_photo(scene, tmp_path / "oblique.png"))
    page.get_by_label("Also mark P6 and P7").check()
    expect(page.locator("#next-point")).to_contain_text("Click P1")

    d.click_photo((truth["p1"][0] + 25, truth["p1"][1] + 18))  # off the corner, dragged there below
    d.click_photo(truth["p2"])
    assert d.canvas_colour_near(np.mean([d.mark("p1"), d.mark("p2")], axis=0), CYAN) > 60  # no region yet
    scale = d.view()[0]
    hover = d.hover_readout(truth["p3"])  # the live readout under the pointer
    assert np.allclose(hover, truth["p3"], atol=1 / scale + 0.05), (hover, truth["p3"])
    _loupe_shows_the_photo_enlarged(d.loupe_pixels(), scene.image, hover)
    d.click_photo((truth["p3"][0] + 60, truth["p3"][1] + 40))  # a slip...
    page.get_by_role("button", name="Undo").click()  # ...taken back
    assert d.mark("p3") is None
    d.click_photo(truth["p3"])
    expect(page.locator("#next-point")).to_contain_text("the same corner as P2")
    d.click_photo(truth["p2"])  # P4: a click on P2 puts it on the very same spot
    assert d.mark("p4") == d.mark("p2")
    # The regions are drawn as clicked: the front's outline (cyan) once P3 is placed, the side's
    # (orange) once P5 is.
    front_top = np.mean([d.mark("p1"), d.mark("p2")], axis=0)  # P1 is still off its corner
    # The side's far edge (P5 to P7): in the two-column layout the short top edge's middle lies
    # under P4's label.
    side_far = np.mean([truth["p5"], truth["p7"]], axis=0)
    assert d.canvas_colour_near(front_top, CYAN) < 40
    assert d.canvas_colour_near(side_far, ORANGE) > 60
    for name in ("p5", "p6", "p7"):
        d.click_photo(truth[name])
    expect(page.locator("#next-point")).to_contain_text("Every point is placed")
    assert d.canvas_colour_near(side_far, ORANGE) < 40

    d.zoom_at(truth["p1"], clicks=3)  # precise corners: zoom in, then drag P1 onto its corner
    assert d.view()[0] > 3 * scale
    d.drag(d.mark("p1"), truth["p1"])
    assert np.allclose(d.mark("p1"), truth["p1"], atol=1 / d.view()[0] + 0.05)
    for name in ("p2", "p3", "p5", "p6", "p7"):
        assert np.allclose(d.mark(name), truth[name], atol=1 / scale + 0.05), name

    page.get_by_label("Scale", exact=True).select_option(label="Shooting distance and focal length")
    page.get_by_label("Shooting distance to the front face (mm)").fill(str(scene.distance_mm))
    page.get_by_label("Focal length", exact=False).fill(str(scene.focal_px))
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        state = d.submit_and_wait()
    assert "Done" in state, state
    body = json.loads(sent.value.post_data)
    spec = ScanSpec.model_validate(body["items"][0])  # what the page sent is a valid job item
    assert spec.focal_px == scene.focal_px and spec.scale.distance_mm == scene.distance_mm
    assert spec.image.startswith("upload:") and spec.side_image is None

    shown = d.dimensions()
    _close(shown, BOX)
    job_id = page.locator("#job-state").text_content().split()[1].rstrip(":")
    job = httpx.get(f"{stack.url}/v1/jobs", headers={"X-API-Key": KEY}).json()["jobs"][0]
    assert job["id"].startswith(job_id)
    result = job["items"][0]["result"]
    assert shown == {k: round(result["dimensions"][k], 2) for k in shown}
    expect(page.locator("#details dd[data-field=points]")).to_have_text(f"{result['points']:,}")
    # The service's default outputs (CSV and PLY), the report and the overlay.
    expect(page.locator(".downloads a")).to_have_text(
        [f"Download {name}" for name in
         ("Cloud (CSV)", "Cloud (PLY)", "Report (JSON)", "Fit overlay (JPEG)")])
    expect(page.locator(f"#jobs tr[data-job='{job['id']}']")).to_contain_text("succeeded")

    pixels = d.viewer_pixels()  # the 3D view rendered: many colours, not one flat fill
    assert pixels.shape[0] > 200 and pixels.shape[1] > 400
    colours = np.unique(pixels.reshape(-1, 3), axis=0)
    assert len(colours) > 50 and pixels.std() > 5, (len(colours), pixels.std())
    page.get_by_label("Point colours").select_option("depth")
    assert not np.array_equal(d.viewer_pixels(), pixels)
    # Orbit (drag) and zoom (wheel) move the camera: the picture changes each time.
    box = page.locator("#viewer canvas").bounding_box()
    centre = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    before = d.settled_view()
    page.mouse.move(*centre)
    page.mouse.down()
    page.mouse.move(centre[0] + 90, centre[1] + 40, steps=6)
    page.mouse.up()
    orbited = d.settled_view(unlike=before)
    assert np.abs(orbited.astype(int) - before).mean() > 1
    page.mouse.wheel(0, -500)
    zoomed = d.settled_view(unlike=orbited)  # drawn on the view's next frames, however late
    assert np.abs(zoomed.astype(int) - orbited).mean() > 1

    # The key stays with the tab (sessionStorage, never the URL): a reload is still logged in,
    # and the job can be opened again from the list of recent jobs.
    assert KEY not in page.url and page.evaluate("sessionStorage.getItem('prism.apiKey')") == KEY
    page.reload()
    page.get_by_role("button", name=f"Open job {job['id'][:8]} (succeeded)").click()
    sigma = result["uncertainty"]["width"]
    expect(page.locator("#dimensions dd[data-field=width]")).to_have_text(
        f"{shown['width']:.2f} ± {sigma:.2f} mm")
    # The fit drawn on the photo, fetched through the API (same origin, same key).
    overlay = page.locator("#overlay")
    expect(page.locator("#overlay-figure")).to_be_visible()
    page.wait_for_function("document.getElementById('overlay').naturalWidth > 0")
    shrink = min(1.0, OVERLAY_MAX_SIDE / max(scene.image.shape[:2]))  # stored at display size
    width = page.evaluate("document.getElementById('overlay').naturalWidth")
    assert width == round(scene.image.shape[1] * shrink)
    assert overlay.get_attribute("src").startswith("blob:")
    page.locator("#result").screenshot(path=str(tmp_path / "result.png"))
    assert d.viewer_pixels().std() > 5


def _loupe_shows_the_photo_enlarged(loupe: np.ndarray, image: np.ndarray, at) -> None:
    """The magnifier holds the photo's own pixels around `at`, 22 across, each a square block."""
    size = loupe.shape[0]
    zoom = size / 22
    ys, xs = np.mgrid[0:size, 0:size]
    # Canvas pixel centre -> image pixel, as loupe.ts draws it (image point x at pixel edge x + 0.5).
    cols = np.floor(at[0] + 0.5 - 11 + (xs + 0.5) / zoom).astype(int)
    rows = np.floor(at[1] + 0.5 - 11 + (ys + 0.5) / zoom).astype(int)
    inside = (cols >= 0) & (cols < image.shape[1]) & (rows >= 0) & (rows < image.shape[0])
    off_cross = (np.abs(xs - size / 2) > 2) & (np.abs(ys - size / 2) > 2)
    want = image[rows.clip(0, image.shape[0] - 1), cols.clip(0, image.shape[1] - 1)]
    same = (np.abs(loupe.astype(int) - want.astype(int)) <= 3).all(axis=-1)
    assert same[inside & off_cross].mean() > 0.9, same[inside & off_cross].mean()


@pytest.mark.parametrize("extra", [False, True], ids=["p1-p5", "p1-p7"])
def test_two_square_photos(page, stack, tmp_path, extra):
    front = render_front_view(BOX, seed=5)
    side = render_side_view(BOX, seed=5)
    d = PageDriver(page)
    d.two_photos(front, side, tmp_path)
    if not extra:  # the page starts with seven points
        page.get_by_label("Also mark P6 and P7").uncheck()
    for name in ("p1", "p2", "p3", "p6")[: 4 if extra else 3]:
        d.click_photo(front.points[name])
    # The side points are marked on the side photo, which the canvas turns to by itself.
    expect(page.get_by_role("button", name="Side photo")).to_have_attribute("aria-pressed", "true")
    for name in ("p4", "p5", "p7")[: 3 if extra else 2]:
        d.click_photo(side.points[name])
    page.get_by_label("Scale", exact=True).select_option(label="Millimetres per pixel")
    page.get_by_label("Millimetres per pixel (front)").fill(str(front.mm_per_px))
    page.get_by_label("Millimetres per pixel (side photo, optional)").fill(str(side.mm_per_px))
    assert "Done" in d.submit_and_wait()
    _close(d.dimensions(), BOX)
    if not extra:
        _a_large_cloud_is_thinned_for_display(page, d)


def _ply(n: int) -> bytes:
    """A binary PLY of n points on a 120 x 80 mm plate, coloured by position."""
    rng = np.random.default_rng(0)
    rows = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                              ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rows["x"], rows["y"] = rng.uniform(0, 120, n), rng.uniform(0, 80, n)
    rows["red"], rows["green"] = rows["x"] * 2, rows["y"] * 3
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
              "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
              "property uchar blue\nend_header\n")
    return header.encode() + rows.tobytes()


def _a_large_cloud_is_thinned_for_display(page, d: PageDriver) -> None:
    # Worker previews stop at 100k points; a larger cloud (an older or another producer's
    # preview) is thinned by the page to every k-th point, at most 200k.
    n, limit = 300_001, 200_000
    big = _ply(n)
    page.route(re.compile(r".*/preview\.ply$"), lambda route: route.fulfill(
        body=big, content_type="application/octet-stream"))
    page.get_by_role("button", name=re.compile(r"Open job \w+ \(succeeded\)")).first.click()
    status = page.locator("#viewer-status")
    expect(status).to_contain_text(f"thinned from {n:,} for display", timeout=30_000)
    kept = math.ceil(n / math.ceil(n / limit))
    assert page.locator("#viewer").get_attribute("data-points") == str(kept)
    assert f"Showing {kept:,}" in status.text_content()
    assert d.viewer_pixels().std() > 5  # drawn, not a flat fill


# Records every value the page gives its progress bar (a property, so no DOM mutation shows it).
_WATCH_PROGRESS = """
const own = Object.getOwnPropertyDescriptor(HTMLProgressElement.prototype, "value");
window.progressSeen = [];
Object.defineProperty(HTMLProgressElement.prototype, "value", {
  get() { return own.get.call(this); },
  set(v) { if (this.id === "job-progress") window.progressSeen.push(v); own.set.call(this, v); },
});
"""


def test_paper_method_volume_cloud_and_a_known_edge(page, stack, tmp_path):
    page.add_init_script(_WATCH_PROGRESS)
    page.reload()
    # Shot from different distances: with one known edge, P7 carries the scale to the side photo.
    # 640 x 512, so the volume cloud stays under the default point limit.
    views = {"image_size": (640, 512), "focal_px": 700.0, "seed": 7}
    front, side = render_front_view(BOX, **views), render_side_view(BOX, **views)
    d = PageDriver(page)
    d.two_photos(front, side, tmp_path)
    page.get_by_label("Also mark P6 and P7").check()
    for name in ("p1", "p2", "p3", "p6"):
        d.click_photo(front.points[name])
    for name in ("p4", "p5", "p7"):
        d.click_photo(side.points[name])
    page.get_by_label("Method").select_option(label="The paper's colour scan")
    page.get_by_label("Cloud", exact=True).select_option(label="Volume: filled through the depth")
    page.get_by_label("Scale", exact=True).select_option(label="One known edge")
    page.get_by_label("Known edge").select_option(label="Width (P1 to P2)")
    page.get_by_label("Its length (mm)").fill("120")
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        state = d.submit_and_wait()
    assert "Done" in state, (state, page.locator("#result").text_content())
    spec = ScanSpec.model_validate(json.loads(sent.value.post_data)["items"][0])
    assert (spec.method, spec.cloud) == ("paper", "volume")
    assert spec.scale.model_dump() == {"kind": "edge", "edge": "width", "length_mm": 120.0}

    shown = d.dimensions()
    assert shown["width"] == 120.0  # the known edge, exactly
    _close(shown, BOX)
    job = httpx.get(f"{stack.url}/v1/jobs", headers={"X-API-Key": KEY}).json()["jobs"][0]
    result = job["items"][0]["result"]
    assert shown == {k: round(result["dimensions"][k], 2) for k in shown}
    expect(page.locator("#details dd[data-field=points]")).to_have_text(f"{result['points']:,}")
    expect(page.locator("#details dd[data-field=point-loss]")).to_have_text(
        f"{result['point_loss'] * 100:.2f} %")
    # The bar followed the job's own progress: never backwards, from running to 100.
    seen = page.evaluate("window.progressSeen")
    assert seen == sorted(seen) and seen[-1] == 100 and min(seen) < 100, seen
    assert d.viewer_pixels().std() > 5

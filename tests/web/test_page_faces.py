"""A left side face marked on the page and measured by the real stack (issue 15, part 3): the
second-face choice, its hints, its outline as clicked, and the dimensions against the rendered box."""

from __future__ import annotations

import json

import numpy as np
from page_driver import PageDriver, save_photo
from playwright.sync_api import expect

from prismcore.spec import ScanSpec
from prismsynth import Box, render_oblique_view

BOX = Box(120.0, 80.0, 60.0)
CYAN, ORANGE = (0, 200, 255), (255, 140, 0)  # the front's and the second face's outlines (marker-draw.ts)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def test_a_left_side_face_marked_on_the_page_is_measured(page, stack, tmp_path):
    scene = render_oblique_view(BOX, yaw_deg=-32.0, pitch_deg=16.0, seed=5, side_face="left")
    truth = {n: scene.points[n] for n in NAMES}
    d = PageDriver(page)
    d.log_in()
    d.add_photos(save_photo(scene, tmp_path / "left.png"))
    page.get_by_label("Also mark P6 and P7").check()
    page.get_by_label("Second face", exact=True).select_option(label="left side (P4 on P1, P5 left of it)")
    expect(page.locator("#row-p5")).to_contain_text("left side face, far upper corner")

    for name in ("p1", "p2", "p3"):
        d.click_photo(truth[name])
    expect(page.locator("#next-point")).to_contain_text("the same corner as P1, so click P1")
    d.click_photo(truth["p1"])  # P4: a click on P1 puts it on the very same spot
    assert d.mark("p4") == d.mark("p1")
    left_top = np.mean([truth["p1"], truth["p5"]], axis=0)  # the left face's upper edge
    assert d.canvas_colour_near(left_top, ORANGE) > 60  # no second face until P5
    d.click_photo(truth["p5"])
    assert d.canvas_colour_near(left_top, ORANGE) < 40  # drawn on the left, as clicked
    for name in ("p6", "p7"):
        d.click_photo(truth[name])
    expect(page.locator("#next-point")).to_contain_text("Every point is placed")
    assert d.canvas_colour_near(np.mean([truth["p5"], truth["p7"]], axis=0), ORANGE) < 40

    page.get_by_label("Scale", exact=True).select_option(label="Shooting distance and focal length")
    page.get_by_label("Shooting distance to the front face (mm)").fill(str(scene.distance_mm))
    page.get_by_label("Focal length", exact=False).fill(str(scene.focal_px))
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        state = d.submit_and_wait()
    assert "Done" in state, state
    spec = ScanSpec.model_validate(json.loads(sent.value.post_data)["items"][0])
    assert spec.side_face == "left"
    got = d.dimensions()
    for k, v in {"width": BOX.width_mm, "height": BOX.height_mm, "depth": BOX.depth_mm}.items():
        assert abs(got[k] / v - 1) < 0.02, (k, got)

"""What each side rests on (the refined edge or the click, and why), and correct clicks kept.

Oracles: renders of a box of known size; drawn faces whose outline is known to the pixel (the
overlay); and real photos (YCB-Video, beside the repository) whose true corners come from the
data's poses, K and model coordinates (`benchmarks/real_clicks_data.py`).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore import ScanSpec, plan_scan
from prismcore.geometry.perspective import NOISE_CLICK_PX
from prismcore.outputs.overlay_report import edge_use_notes, report_notes
from prismcore.report import Fit, ScanReport
from prismsynth import Box, render_oblique_view

_DATA = Path(__file__).resolve().parents[3] / "benchmarks" / "real_clicks_data.py"
_spec = importlib.util.spec_from_file_location("real_clicks_data", _DATA)
assert _spec is not None and _spec.loader is not None
rcd = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("real_clicks_data", rcd)  # its dataclasses look their module up by name
_spec.loader.exec_module(rcd)

# A light face on a dark table, its outline the rectangle x 100-300, y 80-240.
_OUTLINE = np.array([[100.0, 80.0], [300.0, 80.0], [300.0, 240.0], [100.0, 240.0]])


def _face(border_px: float | None = None) -> np.ndarray:
    """The face drawn with 4x supersampling (edges placed to a quarter pixel), optionally a dark
    printed line `border_px` inside its top side."""
    s = 4

    def big(v: float) -> int:  # image px (pixel centres at integers) -> supersampled row/column
        return round((v + 0.5) * s)

    image = np.full((320 * s, 400 * s, 3), 40, np.uint8)
    cv2.rectangle(image, (big(100), big(80)), (big(300) - 1, big(240) - 1), (220, 210, 190), -1)
    if border_px is not None:
        y = big(80 + border_px)
        cv2.rectangle(image, (big(104), y), (big(296), y + s), (150, 30, 30), -1)
    return cv2.resize(image, (400, 320), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("seed", [3, 4])
def test_every_side_says_what_it_rests_on_and_exact_clicks_stay_exact(seed):
    box = Box(150.0, 90.0, 70.0)
    scene = render_oblique_view(box, yaw_deg=30.0, pitch_deg=15.0, seed=seed)
    pts = [list(map(float, scene.points[n])) for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")]
    plan = plan_scan(
        ScanSpec(image="x", points=pts, scale={"kind": "edge", "edge": "width", "length_mm": 150.0}),
        scene.image,
    )
    edges = plan.fit["edges"]
    assert set(edges) == {"front", "side"}
    for sides in edges.values():
        assert [s["side"] for s in sides] == ["top", "right", "bottom", "left"]
        assert all(s["used"] in ("edge", "click") and s["why"] for s in sides)
    assert sum(s["used"] == "edge" for sides in edges.values() for s in sides) >= 6
    assert plan.dimensions.height == pytest.approx(90.0, rel=0.005)
    assert plan.dimensions.depth == pytest.approx(70.0, rel=0.005)
    # Exact clicks are not moved farther than their stated sigma.
    assert max(plan.fit["point_residuals_px"].values()) <= NOISE_CLICK_PX


def test_the_overlay_legend_names_each_faces_edges_and_why():
    fit = {
        "rms_px": 0.5,
        "edges": {
            "front": [
                {"side": "top", "used": "edge", "why": "the outline"},
                {"side": "right", "used": "click", "why": "another edge lies outside the one found"},
                {"side": "bottom", "used": "edge", "why": "the outline"},
                {"side": "left", "used": "click", "why": "another edge lies outside the one found"},
            ]
        },
    }
    assert edge_use_notes(Fit.model_validate(fit)) == [
        "front edges: top, bottom from the photo; "
        "right, left clicked (another edge lies outside the one found)"
    ]
    assert edge_use_notes(Fit()) == [] and edge_use_notes(None) == []
    report = ScanReport.model_validate({"dimensions": {"width": 1, "height": 1, "depth": 1, "unit": "px"},
                                        "fit": fit, "warnings": [], "timings_ms": {}})
    assert report_notes(report)[-1].startswith("front edges: ")


@pytest.mark.parametrize("frame", [1, 4, 7, 10])
@pytest.mark.parametrize("cls", sorted(rcd.OBJECTS))
@pytest.mark.parametrize("focal", [True, False])
@pytest.mark.skipif(not rcd.available(), reason=f"the YCB-Video frames (MIT licence, not in the repository) "
                    f"are not at {rcd.DATA}: see benchmarks/real_clicks_data.py")
def test_real_photos_true_corners_measure_within_one_percent(frame, cls, focal):
    t = rcd.truth(frame, cls)
    extra = {"focal_px": float(rcd.intrinsics()[0, 0])} if focal else {}
    spec = ScanSpec.model_validate(
        {
            "image": "frame.png",
            "points": [list(p) for p in t.points],
            "side_face": t.side_face,
            "scale": {"kind": "edge", "edge": "width", "length_mm": t.sizes_mm[0]},
            **extra,
        }
    )
    plan = plan_scan(spec, rcd.image(frame))
    measured = (plan.dimensions.width, plan.dimensions.height, plan.dimensions.depth)
    for value, true in zip(measured, t.sizes_mm, strict=True):
        assert value == pytest.approx(true, rel=0.01)
    assert set(plan.fit["edges"]) == {"front", "side"}


def test_the_overlay_dashes_the_sides_the_clicks_set_and_only_those():
    from prismcore.outputs.overlay import draw_overlay
    from prismcore.outputs.overlay_report import clicked_sides

    fit = {
        "edges": {
            "front": [
                {"side": s, "used": u, "why": "w"}
                for s, u in zip(
                    ("top", "right", "bottom", "left"), ("edge", "click", "edge", "edge"), strict=True
                )
            ]
        }
    }
    quad = _OUTLINE.tolist()
    assert clicked_sides(Fit.model_validate(fit), {"front": quad}) == {"front": [1]}
    assert clicked_sides(Fit(), {"front": quad}) == {}
    photo = _face()
    plain = draw_overlay(photo, {}, {"front": quad})
    dashed = draw_overlay(photo, {}, {"front": quad}, clicked_sides={"front": [1]})
    changed = np.argwhere(np.any(plain != dashed, axis=2))
    assert changed.size
    # Only along the right side (x = 300), between its corners.
    assert np.abs(changed[:, 1] - 300).max() <= 4
    assert changed[:, 0].min() >= 78 and changed[:, 0].max() <= 242

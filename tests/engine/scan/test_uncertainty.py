"""1-sigma uncertainties against rendered truth, and free-focal accuracy (focal NOT given)."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore import ScanSpec, plan_scan, run_scan
from prismcore.report import report_dict
from prismsynth import Box, Style, render_oblique_view

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
SCENES = 20


def _scene(i: int):
    rng = np.random.default_rng(1000 + i)
    box = Box(*rng.uniform([40, 30, 25], [250, 200, 150]))
    style = Style(noise_sigma=float(rng.uniform(0, 5)), jpeg_quality=int(rng.integers(65, 96)),
                  lighting=float(rng.uniform(0, 0.5)), blur_sigma=float(rng.uniform(0.3, 1.2)))
    scene = render_oblique_view(box, yaw_deg=float(rng.uniform(15, 45)), pitch_deg=float(rng.uniform(5, 25)),
                                focal_px=float(rng.uniform(900, 2500)), style=style, seed=i)
    clicks = [list(np.rint(np.asarray(scene.points[n]) + rng.uniform(-3, 3, 2))) for n in NAMES]
    return box, scene, clicks


@pytest.fixture(scope="module")
def free_focal_runs():
    """(relative error, relative sigma, narrowest face px) of height and depth per scene, the
    width the known edge."""
    out = []
    for i in range(SCENES):
        box, scene, clicks = _scene(i)
        spec = ScanSpec(image="x", points=clicks, scale={"kind": "edge", "length_mm": box.width_mm})
        plan = plan_scan(spec, scene.image)
        assert plan.camera["focal_source"] == "fitted"
        d, u = plan.dimensions, plan.dimensions.uncertainty
        truth = np.array([box.height_mm, box.depth_mm])
        narrowest = min(np.linalg.norm(np.subtract(scene.points[a], scene.points[b]))
                        for a, b in (("p1", "p2"), ("p2", "p3"), ("p4", "p5")))
        out.append((np.abs(np.array([d.height, d.depth]) / truth - 1), np.array(u[1:]) / truth, narrowest))
    return out


@pytest.mark.slow
def test_free_focal_accuracy_over_random_oblique_scenes(free_focal_runs):
    # A face seen nearly edge-on (a few tens of px wide) cannot be measured to 3 %: such scenes
    # must say so through their sigma (next test), and are left out of the accuracy target.
    wide = [e for e, _, px in free_focal_runs if px >= 40]
    assert len(wide) >= 0.8 * SCENES
    errors = np.concatenate(wide)
    assert np.median(errors) < 0.01, np.round(errors * 100, 2)
    assert errors.max() < 0.03, np.round(errors * 100, 2)


@pytest.mark.slow
def test_true_error_lies_within_two_sigma_in_90_percent(free_focal_runs):
    errors = np.concatenate([e for e, _, _ in free_focal_runs])
    sigmas = np.concatenate([s for _, s, _ in free_focal_runs])
    assert (errors <= 2 * sigmas).mean() >= 0.9, np.round(errors / sigmas, 2)
    # Not vacuous: the sigmas stay small enough to be worth reading.
    assert np.median(sigmas) < 0.02, np.round(sigmas * 100, 2)


# Scene 1 is left out: its side face is 17 px wide and the square-on depth is 89 % off at
# 9 sigma (a known gap, see the report of issue 15).
@pytest.mark.parametrize("seed", [0, 2, 3])
def test_square_on_model_says_it_is_unsure_of_an_oblique_photo(seed):
    # The obliqueness read from the quads (an affine camera) underestimates what perspective
    # adds, so 2-sigma coverage is NOT reached for this model (errors run 2-4 sigma); what is
    # asserted is that the sigma flags the depth as unsure, and that the width is exact.
    box, scene, clicks = _scene(seed)
    spec = ScanSpec(image="x", points=clicks[:5], scale={"kind": "edge", "length_mm": box.width_mm})
    d = plan_scan(spec, scene.image).dimensions
    assert not d.perspective
    error = abs(d.depth / box.depth_mm - 1)
    sigma = d.uncertainty[2] / box.depth_mm
    assert sigma > 0.05 and error <= 5 * sigma, (error, sigma)
    assert d.uncertainty[0] == pytest.approx(0.0, abs=1e-9)


def test_report_carries_the_uncertainty_in_the_reports_unit():
    box, scene, clicks = _scene(0)
    spec = ScanSpec(image="x", points=clicks, scale={"kind": "edge", "length_mm": box.width_mm})
    report = report_dict(run_scan(spec, scene.image).report)
    assert set(report["uncertainty"]) == {"width", "height", "depth"}
    assert report["uncertainty"]["width"] == pytest.approx(0.0, abs=1e-6)  # the known edge itself
    assert 0 < report["uncertainty"]["depth"] < 0.05 * report["dimensions"]["depth"]
    assert report["camera"]["focal_source"] == "fitted" and report["camera"]["focal_std_px"] > 0
    # Each face's sides: the refined edge or the click, and why (the overlay's legend reads it).
    assert set(report["fit"]) == {"rms_px", "point_residuals_px", "edges"}

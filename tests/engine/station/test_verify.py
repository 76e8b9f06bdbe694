"""The verification's statistics (prismcore.station.verify) against hand computations: Student's t
quantiles from a printed table (not scipy), means and sample sigmas worked out by hand."""

from __future__ import annotations

import json
from datetime import UTC, datetime

import numpy as np
import pytest

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.station.board import default_board
from prismcore.station.calibrate import PlanePose, Station
from prismcore.station.verify import (
    bias_interval,
    check_placements,
    percent_grr,
    repeatability,
    verify_dimension,
    verify_placements,
    within_sigma,
    yaw_spread_deg,
)

# t(0.975, dof) from a printed table of Student's t
T975 = {4: 2.776445, 6: 2.446912, 9: 2.262157}


@pytest.mark.parametrize(
    ("errors", "mean", "sigma", "dof"),
    [
        # mean 0.3; squares about it .04+.01+0+.01+.04 = .10, /4 -> s = sqrt(.025)
        ([0.1, 0.2, 0.3, 0.4, 0.5], 0.3, 0.158113883, 4),
        # mean 0; squares .04+.01+0+.09+.01+.04+.09 = .28, /6 -> s = sqrt(.046667)
        ([-0.2, 0.1, 0.0, 0.3, -0.1, 0.2, -0.3], 0.0, 0.216024690, 6),
        # 0.01..0.10: mean .055; squares sum 0.00825, /9 -> s = sqrt(.000916667)
        ([0.01 * k for k in range(1, 11)], 0.055, 0.0302765035, 9),
    ],
)
def test_bias_interval_and_repeatability_match_the_hand_computation(errors, mean, sigma, dof):
    half = T975[dof] * sigma / np.sqrt(len(errors))
    bias, low, high = bias_interval(errors)
    assert bias == pytest.approx(mean, abs=1e-12)
    assert (low, high) == pytest.approx((mean - half, mean + half), abs=1e-6)
    assert repeatability(errors) == pytest.approx(sigma, rel=1e-8)


@pytest.mark.parametrize(
    ("sigma", "width", "expected"), [(0.1, 2.0, 30.0), (0.05, 1.0, 30.0), (0.02, 4.0, 3.0), (0.5, 3.0, 100.0)]
)
def test_percent_grr_is_six_sigma_over_the_tolerance_width(sigma, width, expected):
    assert percent_grr(sigma, width) == pytest.approx(expected)


def test_percent_grr_refuses_a_tolerance_that_is_not_positive():
    with pytest.raises(InputError, match="positive"):
        percent_grr(0.1, 0.0)


@pytest.mark.parametrize(
    ("errors", "sigmas", "expected"),
    [
        ([0.3, -0.61, 0.6], [0.1, 0.2, 0.2], [True, False, True]),  # on the line counts as within
        ([-0.9, 0.0], [0.2, 0.01], [False, True]),
    ],
)
def test_within_sigma_compares_each_error_with_its_own_sigma(errors, sigmas, expected):
    assert within_sigma(errors, sigmas).tolist() == expected


@pytest.mark.parametrize(
    ("yaws", "spread"),
    [
        ([10, 20, 170], 30.0),  # gaps 10, 150, 20 on the half turn: 180 - 150
        ([0, 90], 90.0),
        ([5, 5, 5], 0.0),
        ([179, 1, 181], 2.0),
        ([0, 45, 90, 135], 135.0),
    ],
)
def test_yaw_spread_is_taken_on_the_half_turn(yaws, spread):
    assert yaw_spread_deg(yaws) == pytest.approx(spread)


BOARD = (210.0, 150.0)  # diagonal 258.07 mm: 1/8 is 32.26 mm
SPREAD = [(50, 40), (160, 40), (105, 75), (50, 110), (160, 110)]  # RMS from the mean: 62.5 mm
TURNED = [10, 40, 70, 100, 130]


@pytest.mark.parametrize(
    ("positions", "yaws", "reason"),
    [
        (SPREAD[:4], TURNED[:4], "4 placements"),
        ([(100 + k, 75 - k) for k in range(5)], TURNED, "centres lie 2 mm"),  # RMS sqrt(2) * sqrt(2) = 2 mm
        (SPREAD, [10, 15, 20, 25, 30], "yaws span 20 deg"),
        (SPREAD, [170, 175, 0, 5, 10], "yaws span 20 deg"),
    ],  # across 0 deg
)
def test_check_placements_refuses_with_the_reason(positions, yaws, reason):
    with pytest.raises(InputError, match=reason):
        check_placements(positions, yaws, BOARD)


def test_check_placements_accepts_placements_spread_over_the_support():
    check_placements(SPREAD, TURNED, BOARD)


def test_a_small_significant_bias_is_accepted_a_large_one_is_not():
    # bias 0.3, s = sqrt(.001) = 0.0316228, CI 0.3 -+ 2.776445 * 0.0141421 (s / sqrt 5): significant
    measured = 30.0 + np.array([0.26, 0.28, 0.30, 0.32, 0.34])
    sigmas = np.full(5, 0.2)
    ok = verify_dimension(measured, sigmas, 30.0, tolerance=2.0)  # 10 % of 4 mm = 0.4 >= 0.3
    assert ok.verified and ok.failures == []
    assert ok.bias_ci95_mm == pytest.approx((0.3 - 0.0392649, 0.3 + 0.0392649), abs=1e-6)
    assert ok.grr_percent == pytest.approx(6 * 0.0316228 / 4 * 100, rel=1e-5)  # 4.74 %
    bad = verify_dimension(measured, sigmas, 30.0, tolerance=1.0)  # 10 % of 2 mm = 0.2 < 0.3
    assert not bad.verified and len(bad.failures) == 1 and "bias +0.300" in bad.failures[0]
    none = verify_dimension(measured, sigmas, 30.0, tolerance=None)
    assert not none.verified and none.grr_percent is None and "excludes 0" in none.failures[0]


def test_grr_over_30_percent_and_a_placement_outside_3_sigma_each_fail():
    errors = np.array([-0.2, 0.1, 0.0, 0.3, -0.1, 0.2, -0.3])  # s = 0.216: %GRR 6 * .216 / 2 = 64.8 %
    sigmas = np.array([0.2, 0.2, 0.2, 0.09, 0.2, 0.2, 0.2])  # placement 4: 0.3 > 3 * 0.09
    done = verify_dimension(45.0 + errors, sigmas, 45.0, tolerance=1.0)
    assert done.grr_percent == pytest.approx(64.807407, rel=1e-6)
    assert done.within_3_sigma == [True, True, True, False, True, True, True]
    assert not done.verified
    assert [f.split(" ")[0] for f in done.failures] == ["%GRR", "placement"]
    assert "placement 4 off by more than 3" in done.failures[1]
    unbiased = verify_dimension(45.0 + errors, np.full(7, 0.2), 45.0, tolerance=None)
    assert unbiased.verified  # mean 0: not significant; no tolerance, no %GRR
    assert "alone" not in done.failures[0]  # no one placement makes that spread


def test_grr_over_30_percent_by_one_placement_names_it():
    # a correct station's 7 readings, one of them vague (stated sigma 2.3 mm) and 0.79 mm off
    errors = np.array([-0.035, 0.79, -0.014, 0.022, -0.053, -0.004, -0.035])
    sigmas = np.array([0.38, 2.29, 0.34, 0.35, 0.41, 0.35, 0.33])
    done = verify_dimension(45.0 + errors, sigmas, 45.0, tolerance=2.0)
    without = 6 * np.std(np.delete(errors, 1), ddof=1) / 4 * 100
    assert done.grr_percent > 30 and without < 30 and not done.verified
    assert done.failures == [
        f"%GRR {done.grr_percent:.1f} % is over 30 % (placement 2 alone: off by +0.790 mm, its stated "
        f"sigma 2.290 mm; {without:.1f} % without it: place it again)"
    ]


def _placements(errors: np.ndarray) -> dict[str, object]:
    reference = (70.0, 45.0, 30.0)
    return {
        "measured": np.asarray(reference) + errors,
        "sigmas": np.full(errors.shape, 0.2),
        "reference": reference,
        "positions_mm": SPREAD,
        "yaws_deg": TURNED,
        "board_size_mm": BOARD,
        "photos": [f"{k}.jpg" for k in range(1, 6)],
        "date": datetime(2025, 3, 4, 5, 6, tzinfo=UTC),
    }


def test_verify_placements_names_each_failed_clause_and_round_trips_in_station_json():
    spread = np.array([0.02, -0.01, 0.0, 0.01, -0.02])
    errors = np.column_stack([spread, -spread, 1.0 + spread])  # height 1 mm long
    done = verify_placements(**_placements(errors), tolerance=1.0)  # type: ignore[arg-type]
    assert not done.verified
    assert [d.verified for d in done.dimensions.values()] == [True, True, False]
    assert done.decided_by and all(c.startswith("height: ") for c in done.decided_by)
    assert done.reference_mm == {"width": 70.0, "depth": 45.0, "height": 30.0}
    camera = CameraModel(fx=1000, fy=1000, cx=320, cy=240, image_width=640, image_height=480)
    plane = PlanePose(rvec=[0, 0, 0], tvec=[0, 0, 500], rms_px=0.1, corners=24)
    station = Station(board=default_board(), camera=camera, plane=plane, verification=done)
    again = Station.model_validate_json(station.model_dump_json())
    assert again.verification == done
    # A station.json written before verifications existed still loads: the field is optional.
    old = json.loads(station.model_dump_json())
    del old["verification"]
    assert Station.model_validate(old).verification is None


def test_verify_placements_refuses_a_reference_narrower_than_deep():
    args = _placements(np.zeros((5, 3)))
    args["reference"] = (45.0, 70.0, 30.0)
    with pytest.raises(InputError, match="width 45 is under its depth 70"):
        verify_placements(**args, tolerance=1.0)  # type: ignore[arg-type]

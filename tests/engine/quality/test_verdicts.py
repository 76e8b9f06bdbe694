"""Quality verdicts against a hand oracle: the limits, zero sigma, unknown sigma, per-dimension tolerances."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from prismcore import InputError, ScanSpec
from prismcore.quality.verdicts import COVERAGE_K, judge, quality_block, quality_from_report

# (measured, nominal, tolerance, sigma, verdict), worked out by hand with k = 2:
# pass iff |d| + 2s <= T, fail iff |d| - 2s > T, else uncertain.
ORACLE = [
    (100.0, 100.0, 0.1, 0.0, "pass"),  # on the nominal
    (100.1, 100.0, 0.1, 0.0, "pass"),  # exactly at the upper limit, no sigma: limits are inclusive
    (99.9, 100.0, 0.1, 0.0, "pass"),  # exactly at the lower limit
    (100.3, 100.0, 0.3, 0.0, "pass"),  # 100.3 - 100 is 0.30000000000001137 in binary: still at the limit
    (100.1001, 100.0, 0.1, 0.0, "fail"),  # just beyond, no sigma: no "uncertain" without sigma
    (99.8999, 100.0, 0.1, 0.0, "fail"),
    (100.05, 100.0, 0.1, 0.025, "pass"),  # interval [0.0, 0.1] touches the limit from inside
    (100.05, 100.0, 0.1, 0.026, "uncertain"),  # interval [-0.002, 0.102] straddles it
    (100.2, 100.0, 0.1, 0.05, "uncertain"),  # interval [0.1, 0.3] touches it from outside
    (100.2, 100.0, 0.1, 0.049, "fail"),  # interval [0.102, 0.298] wholly outside
    (99.8, 100.0, 0.1, 0.049, "fail"),
    (100.0, 100.0, 0.1, 1.0, "uncertain"),  # on the nominal but far too unsure
    (100.0, 100.0, 0.0, 0.0, "pass"),  # zero tolerance: only the exact value passes
    (100.0001, 100.0, 0.0, 0.0, "fail"),
    (100.05, 100.0, 0.1, None, "pass"),  # sigma unknown: judged on the value
    (100.15, 100.0, 0.1, None, "fail"),
    (100.1, 100.0, 0.1, None, "pass"),
]


@pytest.mark.parametrize(("measured", "nominal", "tolerance", "sigma", "verdict"), ORACLE)
def test_judge_matches_the_hand_oracle(measured, nominal, tolerance, sigma, verdict):
    assert COVERAGE_K == 2.0
    assert judge(measured, nominal, tolerance, sigma) == verdict


@pytest.mark.parametrize(("measured", "nominal", "tolerance", "sigma", "verdict"), ORACLE)
def test_judge_is_symmetric_about_the_nominal(measured, nominal, tolerance, sigma, verdict):
    assert judge(2 * nominal - measured, nominal, tolerance, sigma) == verdict


@pytest.mark.parametrize("bad", [
    {"measured": math.nan}, {"nominal": math.inf}, {"tolerance": -0.1}, {"sigma": -1.0},
    {"sigma": math.nan}, {"k": 0.0},
])
def test_bad_numbers_are_refused(bad):
    args = {"measured": 100.0, "nominal": 100.0, "tolerance": 0.1, "sigma": 0.01, "k": 2.0} | bad
    with pytest.raises(InputError):
        judge(**args)


def test_block_per_dimension_tolerances_counts_and_overall_verdict():
    block = quality_block({"width": 120.05, "height": 80.4, "depth": 60.0, "unit": "mm"},
                          {"width": 0.01, "height": 0.01, "depth": 0.2},
                          [120.0, 80.0, 60.0], [0.1, 0.2, 0.3])
    rows = block["dimensions"]
    assert [rows[n]["verdict"] for n in ("width", "height", "depth")] == ["pass", "fail", "uncertain"]
    assert block["counts"] == {"pass": 1, "fail": 1, "uncertain": 1}
    assert block["verdict"] == "fail"
    assert block["k"] == 2.0
    assert rows["width"] == {"nominal_mm": 120.0, "measured_mm": 120.05, "deviation_mm": 0.05,
                             "tolerance_mm": 0.1, "sigma_mm": 0.01, "interval_mm": [0.03, 0.07],
                             "verdict": "pass"}
    assert rows["height"]["deviation_mm"] == pytest.approx(0.4)
    assert rows["depth"]["interval_mm"] == [-0.4, 0.4]


def test_block_overall_uncertain_without_a_fail_and_one_tolerance_for_all():
    block = quality_block({"width": 10.0, "height": 10.0, "depth": 10.2}, None, [10, 10, 10], 0.1)
    assert [r["tolerance_mm"] for r in block["dimensions"].values()] == [0.1, 0.1, 0.1]
    assert [r["sigma_mm"] for r in block["dimensions"].values()] == [None, None, None]
    assert block["verdict"] == "fail"
    block = quality_block({"width": 10.0, "height": 10.0, "depth": 10.05},
                          {"width": 0.0, "height": 0.0, "depth": 0.1}, [10, 10, 10], 0.1)
    assert block["verdict"] == "uncertain"
    assert block["counts"] == {"pass": 2, "fail": 0, "uncertain": 1}


def test_report_block_needs_mm_and_is_none_without_a_nominal():
    report = {"dimensions": {"width": 1.0, "height": 2.0, "depth": 3.0, "unit": "px"}, "uncertainty": None}
    assert quality_from_report(report, None, None) is None
    with pytest.raises(InputError, match="px"):
        quality_from_report(report, [1, 2, 3], 0.1)


POINTS = [[10, 10], [100, 10], [100, 80], [100, 10], [130, 5]]


@pytest.mark.parametrize(("extra", "message"), [
    ({"nominal": [1, 2, 3]}, "nominal needs tolerance_mm"),
    ({"tolerance_mm": 0.1}, "tolerance_mm needs nominal"),
    ({"nominal": [1, 2], "tolerance_mm": 0.1}, "nominal"),
    ({"nominal": [1, 2, 0], "tolerance_mm": 0.1}, "greater than 0"),
    ({"nominal": [1, 2, 3], "tolerance_mm": [0.1, 0.2]}, "tolerance_mm"),
    ({"nominal": [1, 2, 3], "tolerance_mm": -0.1}, "tolerance_mm"),
    ({"spacing_mm": 0}, "spacing_mm"),
])
def test_spec_refuses_bad_quality_fields(extra, message):
    with pytest.raises(ValidationError, match=message):
        ScanSpec.model_validate({"image": "a.png", "points": POINTS,
                                 "scale": {"kind": "mm_per_px", "front": 0.1}, **extra})


@pytest.mark.parametrize("extra", [{"nominal": [1, 2, 3], "tolerance_mm": 0.1}, {"spacing_mm": 1.0},
                                   {"formats": ["laz"]}, {"formats": ["csv", "glb"]}])
def test_metric_fields_need_a_scale(extra):
    with pytest.raises(ValidationError, match="without a scale"):
        ScanSpec.model_validate({"image": "a.png", "points": POINTS, **extra})


def test_spec_accepts_the_fields_and_round_trips():
    spec = ScanSpec.model_validate({"image": "a.png", "points": POINTS,
                                    "scale": {"kind": "mm_per_px", "front": 0.1},
                                    "nominal": [120, 80, 60], "tolerance_mm": [0.1, 0.2, 0.3],
                                    "spacing_mm": 0.5, "formats": ["laz", "glb", "las"]})
    assert spec.nominal == (120.0, 80.0, 60.0) and spec.tolerance_mm == (0.1, 0.2, 0.3)
    assert ScanSpec.model_validate_json(spec.model_dump_json()) == spec

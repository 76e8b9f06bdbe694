"""Quality control: each measured dimension against its nominal size and tolerance.

A dimension *passes* when its whole uncertainty interval lies within the tolerance limits, *fails*
when the whole interval lies outside them, and is *uncertain* when the interval straddles a limit.
The interval is the deviation ± ``k`` standard deviations with ``k`` = :data:`COVERAGE_K` = 2
(about 95 % for a normal error: the usual expanded uncertainty of ISO/IEC Guide 98-3, and the
guard band ISO 14253-1 applies at the limits).

Limits are inclusive: a deviation exactly at ``± tolerance`` (with zero sigma) passes, and an
interval whose far end touches a limit from outside is uncertain, not failed. Comparisons allow
:data:`EPSILON_MM` so that binary rounding (``100.3 - 100`` is ``0.30000000000001137``) does not
decide a verdict. A dimension without an uncertainty (no fit covariance: e.g. a scan without
perspective correction) is judged on its value alone, and its row says ``"sigma_mm": null``.

Pure functions over plain numbers; :func:`quality_block` returns report.json's ``quality`` block.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal, TypedDict

from prismcore.errors import InputError
from prismcore.report import Quality, ScanReport

__all__ = ["COVERAGE_K", "DIMENSIONS", "EPSILON_MM", "DimensionVerdict", "QualityBlock", "Verdict",
           "judge", "quality_block", "quality_from_report", "report_quality"]

COVERAGE_K = 2.0
"""Coverage factor: the measurement's interval is value ± COVERAGE_K * sigma (about 95 %)."""

EPSILON_MM = 1e-9
"""Slack in every comparison with a limit, mm (a nanometre: far below any measurement)."""

DIMENSIONS = ("width", "height", "depth")
"""The order of nominal and tolerance triples: the report's dimension order."""

Verdict = Literal["pass", "fail", "uncertain"]


class DimensionVerdict(TypedDict):
    """One dimension's row of the quality block (all lengths in mm, rounded to 4 decimals).

    ``interval_mm`` is [deviation - k*sigma, deviation + k*sigma] (just the deviation twice when
    sigma is unknown); ``sigma_mm`` is null when the report has no uncertainty for it.
    """

    nominal_mm: float
    measured_mm: float
    deviation_mm: float
    tolerance_mm: float
    sigma_mm: float | None
    interval_mm: list[float]
    verdict: Verdict


class QualityBlock(TypedDict):
    """report.json's ``quality``: ``verdict`` is the part's: fail if any dimension fails, else
    uncertain if any is uncertain, else pass; ``counts`` counts the dimensions per verdict (all
    three keys always present); ``k`` is the coverage factor used."""

    verdict: Verdict
    k: float
    counts: dict[str, int]
    dimensions: dict[str, DimensionVerdict]


def judge(measured: float, nominal: float, tolerance: float, sigma: float | None,
          k: float = COVERAGE_K) -> Verdict:
    """The verdict of one dimension.

    Parameters
    ----------
    measured, nominal : float
        mm.
    tolerance : float
        Allowed |measured - nominal|, mm, >= 0 (the limits are inclusive).
    sigma : float or None
        One standard deviation of `measured`, mm, >= 0; None when unknown (judged on the value).
    k : float
        Coverage factor.

    Raises
    ------
    InputError
        A non-finite value, a negative tolerance or sigma, or a non-positive k.
    """
    for name, value in (("measured", measured), ("nominal", nominal), ("tolerance", tolerance),
                        ("k", k)):
        if not math.isfinite(value):
            raise InputError(f"{name} must be a finite number, got {value!r}")
    if tolerance < 0:
        raise InputError(f"tolerance must be >= 0 mm, got {tolerance!r}")
    if k <= 0:
        raise InputError(f"k must be > 0, got {k!r}")
    if sigma is not None and not (math.isfinite(sigma) and sigma >= 0):
        raise InputError(f"sigma must be a finite number >= 0 mm or None, got {sigma!r}")
    off = abs(measured - nominal)
    half = 0.0 if sigma is None else k * sigma
    if off + half <= tolerance + EPSILON_MM:
        return "pass"
    if off - half > tolerance + EPSILON_MM:
        return "fail"
    return "uncertain"


def _triple(value: float | Sequence[float], name: str) -> tuple[float, float, float]:
    if isinstance(value, int | float):
        return (float(value),) * 3
    values = tuple(float(v) for v in value)
    if len(values) != 3:
        raise InputError(f"{name} needs 3 values (width, height, depth), got {len(values)}")
    return values[0], values[1], values[2]


def quality_block(measured: Mapping[str, float], sigma: Mapping[str, float] | None,
                  nominal: Sequence[float], tolerance: float | Sequence[float],
                  k: float = COVERAGE_K) -> QualityBlock:
    """Deviation and verdict per dimension, and the part's verdict.

    Parameters
    ----------
    measured : mapping
        {"width": mm, "height": mm, "depth": mm} (report.json's ``dimensions``; other keys ignored).
    sigma : mapping or None
        The same keys, one standard deviation each (report.json's ``uncertainty``); None, or a
        missing key, for unknown.
    nominal : (3,) floats
        Nominal width, height, depth, mm.
    tolerance : float or (3,) floats
        One tolerance for all three dimensions, or one each, mm.
    """
    nominal3 = _triple(nominal, "nominal")
    tolerance3 = _triple(tolerance, "tolerance")
    rows: dict[str, DimensionVerdict] = {}
    counts = {"pass": 0, "fail": 0, "uncertain": 0}
    for name, nom, tol in zip(DIMENSIONS, nominal3, tolerance3, strict=True):
        if name not in measured:
            raise InputError(f"no measured {name}")
        value = float(measured[name])
        s = None if sigma is None or sigma.get(name) is None else float(sigma[name])
        verdict = judge(value, nom, tol, s, k)
        deviation = value - nom
        half = 0.0 if s is None else k * s
        rows[name] = {
            "nominal_mm": nom, "measured_mm": value, "deviation_mm": round(deviation, 4),
            "tolerance_mm": tol, "sigma_mm": s,
            "interval_mm": [round(deviation - half, 4), round(deviation + half, 4)],
            "verdict": verdict,
        }
        counts[verdict] += 1
    overall: Verdict = "fail" if counts["fail"] else "uncertain" if counts["uncertain"] else "pass"
    return {"verdict": overall, "k": k, "counts": counts, "dimensions": rows}


def quality_from_report(report: Mapping[str, Any], nominal: Sequence[float] | None,
                        tolerance: float | Sequence[float] | None) -> QualityBlock | None:
    """The quality block of a report dict (its rounded ``dimensions`` and ``uncertainty``, so the
    verdicts agree with the figures shown), or None when no nominal is given.

    Raises
    ------
    InputError
        A nominal for a report in pixels (no scale), or a nominal without a tolerance.
    """
    if nominal is None:
        return None
    if tolerance is None:
        raise InputError("a nominal size needs a tolerance_mm")
    dims = report["dimensions"]
    if dims.get("unit") != "mm":
        raise InputError(f"the dimensions are in {dims.get('unit')!r}, not mm: a nominal size in mm "
                         "needs a scale")
    return quality_block(dims, report.get("uncertainty"), nominal, tolerance)


def report_quality(report: ScanReport, nominal: Sequence[float] | None,
                   tolerance: float | Sequence[float] | None) -> Quality | None:
    """`quality_from_report` of a typed report: its ``quality`` block, or None without a nominal."""
    if nominal is None:
        return None
    sigma = None if report.uncertainty is None else report.uncertainty.model_dump()
    block = quality_from_report({"dimensions": report.dimensions.model_dump(), "uncertainty": sigma},
                                nominal, tolerance)
    return None if block is None else Quality.model_validate(block)

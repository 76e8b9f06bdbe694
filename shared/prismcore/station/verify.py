"""A station verified with a reference part of known size: the statistics of a bias and
repeatability study (AIAG MSA), over a reference part measured in several placements.

Each placement gives, per dimension, the measured value and its stated one sigma; the error is the
measured value minus the reference's. Per dimension:

* bias: the mean error, with its 95 % confidence interval from Student's t (n - 1 degrees of
  freedom): ``bias +- t(0.975, n - 1) * s / sqrt(n)``;
* repeatability: ``s``, the sample standard deviation of the errors over the placements (n - 1);
* each placement's error within 3 times its own stated sigma, or not;
* %GRR against the tolerance, AIAG MSA's formula ``%GRR = 6 * sigma_GRR / tolerance * 100``, the
  tolerance its full width (2T for +-T), sigma_GRR here the repeatability alone (one station,
  one operator: no reproducibility term).

The verdict's rule is ``RULE``. Pure functions over arrays; the record stored in station.json is
``Verification``.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime

import numpy as np
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field, field_validator

from prismcore.errors import InputError

__all__ = [
    "BIAS_SHARE",
    "CONFIDENCE",
    "DIMENSIONS",
    "GRR_FORMULA",
    "MAX_GRR_PERCENT",
    "MIN_PLACEMENTS",
    "MIN_SPREAD_SHARE",
    "MIN_YAW_SPREAD_DEG",
    "RULE",
    "SIGMA_MULTIPLE",
    "DimensionVerification",
    "Verification",
    "bias_interval",
    "check_count",
    "check_placements",
    "percent_grr",
    "repeatability",
    "verify_dimension",
    "verify_placements",
    "within_sigma",
    "yaw_spread_deg",
]

DIMENSIONS = ("width", "depth", "height")  # the station's order: width >= depth, then height
MIN_PLACEMENTS = 5
CONFIDENCE = 0.95
SIGMA_MULTIPLE = 3.0  # each placement's error within this many of its own stated sigma
BIAS_SHARE = 0.10  # a significant bias is still accepted when under this share of the tolerance (2T)
MAX_GRR_PERCENT = 30.0  # AIAG MSA: under 10 % acceptable, 10-30 % may be, over 30 % unacceptable
MIN_SPREAD_SHARE = 1 / 8  # the centres' RMS distance from their mean, over the board's diagonal
MIN_YAW_SPREAD_DEG = 30.0  # the yaws' spread on the half turn (a box turned 180 deg is the same)

GRR_FORMULA = (
    "%GRR = 6 x repeatability / tolerance x 100, the tolerance its full width (2T for +-T); "
    "AIAG MSA's formula with repeatability alone (one station, one operator)"
)
RULE = (
    "verified when width, depth and height each have: a bias whose 95 % confidence interval "
    "contains 0, or whose size is at most 10 % of the tolerance (2T); %GRR at most 30 %; and "
    "every placement's error within 3 times its own stated sigma (with no tolerance given, "
    "the bias must not be significant and %GRR is not judged)"
)


class DimensionVerification(BaseModel):
    """One dimension's figures over the placements, mm."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    reference_mm: float
    mean_mm: float = Field(description="The mean measured value.")
    bias_mm: float = Field(description="The mean error (measured - reference).")
    bias_ci95_mm: tuple[float, float] = Field(
        description="The bias's 95 % confidence interval (Student's t)."
    )
    repeatability_mm: float = Field(description="The errors' sample standard deviation over the placements.")
    errors_mm: list[float] = Field(description="Each placement's error.")
    sigmas_mm: list[float] = Field(description="Each placement's stated one sigma.")
    within_3_sigma: list[bool] = Field(description="Each placement's error within 3 x its stated sigma.")
    grr_percent: float | None = Field(
        description="%GRR against the tolerance (GRR_FORMULA); None without one."
    )
    verified: bool
    failures: list[str] = Field(default_factory=list, description="The rule's clauses this dimension fails.")


class Verification(BaseModel):
    """A station's verification with a reference part: station.json's ``verification``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    date: datetime = Field(description="When it was made (UTC).")
    reference_mm: dict[str, float] = Field(description="The reference part's width, depth and height.")
    tolerance_mm: float | None = Field(
        description="T of +-T (the tolerance's full width is 2T); None if none."
    )
    photos: list[str] = Field(description="The placements' photos, in order.")
    positions_mm: list[tuple[float, float]] = Field(description="Each placement's centre on the support.")
    yaws_deg: list[float] = Field(description="Each placement's yaw.")
    dimensions: dict[str, DimensionVerification] = Field(
        description="width, depth and height, each once.",
        # the keys as the validator takes them, so the published schema says what is accepted
        json_schema_extra={"required": list(DIMENSIONS), "propertyNames": {"enum": list(DIMENSIONS)}},
    )
    verified: bool
    rule: str = RULE
    grr_formula: str = GRR_FORMULA
    decided_by: list[str] = Field(description="The clauses failed (empty when verified).")

    @field_validator("dimensions")
    @classmethod
    def _three(cls, value: dict[str, DimensionVerification]) -> dict[str, DimensionVerification]:
        # every reader (a measurement's verification status, prism station show) takes all three
        if set(value) != set(DIMENSIONS):
            raise ValueError(f"expected width, depth and height, got {', '.join(map(str, value)) or 'none'}")
        return value


def _finite_1d(values: ArrayLike, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 1 or not np.all(np.isfinite(array)):
        raise InputError(f"{name}: expected a 1-D array of finite numbers")
    return array


def bias_interval(errors: ArrayLike, confidence: float = CONFIDENCE) -> tuple[float, float, float]:
    """The mean error and its two-sided confidence interval from Student's t.

    Parameters
    ----------
    errors : array_like, shape (n,)
        Measured minus reference, n >= 2.
    confidence : float
        The interval's coverage, e.g. 0.95.

    Returns
    -------
    bias, low, high : float
        ``mean(errors)`` and ``mean -+ t(1 - (1 - confidence) / 2, n - 1) * s / sqrt(n)`` with ``s``
        the sample standard deviation (n - 1).
    """
    from scipy import stats

    e = _finite_1d(errors, "errors")
    if e.size < 2:
        raise InputError(f"a bias's interval needs 2 errors at least, got {e.size}")
    bias = float(e.mean())
    half = float(stats.t.ppf(1 - (1 - confidence) / 2, e.size - 1)) * repeatability(e) / np.sqrt(e.size)
    return bias, bias - half, bias + half


def repeatability(errors: ArrayLike) -> float:
    """The sample standard deviation (n - 1) of `errors`, shape (n,), n >= 2: the repeatability."""
    e = _finite_1d(errors, "errors")
    if e.size < 2:
        raise InputError(f"a repeatability needs 2 values at least, got {e.size}")
    return float(np.std(e, ddof=1))


def within_sigma(errors: ArrayLike, sigmas: ArrayLike, multiple: float = SIGMA_MULTIPLE) -> np.ndarray:
    """Whether each ``|error| <= multiple * sigma`` (bool, shape (n,)); sigmas are each one's own."""
    e, s = _finite_1d(errors, "errors"), _finite_1d(sigmas, "sigmas")
    if e.shape != s.shape:
        raise InputError(f"{e.size} errors but {s.size} sigmas")
    inside: np.ndarray = np.abs(e) <= multiple * s
    return inside


def percent_grr(sigma_grr: float, tolerance_width: float) -> float:
    """AIAG MSA's %GRR: ``6 * sigma_grr / tolerance_width * 100``.

    Parameters
    ----------
    sigma_grr : float
        The gauge's standard deviation (here the repeatability).
    tolerance_width : float
        The tolerance's full width, USL - LSL (2T for +-T), > 0.
    """
    if not tolerance_width > 0:
        raise InputError(f"a tolerance's width must be positive, got {tolerance_width:g}")
    return 6.0 * sigma_grr / tolerance_width * 100.0


def verify_dimension(
    measured: ArrayLike, sigmas: ArrayLike, reference: float, tolerance: float | None
) -> DimensionVerification:
    """One dimension's bias, repeatability, 3-sigma checks, %GRR and verdict (``RULE``).

    Parameters
    ----------
    measured, sigmas : array_like, shape (n,)
        Each placement's measured value and its stated one sigma, mm; n >= 2.
    reference : float
        The reference part's true value, mm.
    tolerance : float or None
        T of +-T, mm (the tolerance's width is 2T); None: no %GRR, the bias must not be significant.
    """
    m = _finite_1d(measured, "measured")
    s = _finite_1d(sigmas, "sigmas")
    errors = m - reference
    bias, low, high = bias_interval(errors)
    sigma_r = repeatability(errors)
    inside = within_sigma(errors, s)
    failures: list[str] = []
    significant = not low <= 0.0 <= high
    grr = None
    if tolerance is not None:
        grr = percent_grr(sigma_r, 2 * tolerance)
        allowed = BIAS_SHARE * 2 * tolerance
        if significant and abs(bias) > allowed:
            failures.append(
                f"bias {bias:+.3f} mm is significant (95 % CI [{low:+.3f}, {high:+.3f}]) and over "
                f"10 % of the tolerance ({allowed:.3f} mm)"
            )
        if grr > MAX_GRR_PERCENT:
            failures.append(f"%GRR {grr:.1f} % is over {MAX_GRR_PERCENT:g} %"
                            + _one_placement(errors, s, tolerance))
    elif significant:
        failures.append(f"bias {bias:+.3f} mm is significant (95 % CI [{low:+.3f}, {high:+.3f}] excludes 0)")
    outside = [i + 1 for i in np.flatnonzero(~inside)]
    if outside:
        failures.append(
            f"placement{'s' if len(outside) > 1 else ''} {', '.join(map(str, outside))} "
            f"off by more than {SIGMA_MULTIPLE:g} x {'their' if len(outside) > 1 else 'its'} stated sigma"
        )
    return DimensionVerification(
        reference_mm=float(reference),
        mean_mm=float(m.mean()),
        bias_mm=bias,
        bias_ci95_mm=(low, high),
        repeatability_mm=sigma_r,
        errors_mm=[float(v) for v in errors],
        sigmas_mm=[float(v) for v in s],
        within_3_sigma=[bool(v) for v in inside],
        grr_percent=grr,
        verified=not failures,
        failures=failures,
    )


def _one_placement(errors: np.ndarray, sigmas: np.ndarray, tolerance: float) -> str:
    """Where one placement alone takes %GRR over the limit: it named, with its error and stated
    sigma and the %GRR without it. A station calls some readings vague (a face seen edge-on): one
    such among 7 can fail a correct station, and the user should measure it again before blaming
    the station. The verdict is not changed: the reading is the station's."""
    if errors.size < 3:
        return ""
    rest = [percent_grr(repeatability(np.delete(errors, i)), 2 * tolerance) for i in range(errors.size)]
    i = int(np.argmin(rest))
    if rest[i] > MAX_GRR_PERCENT:
        return ""
    return (f" (placement {i + 1} alone: off by {errors[i]:+.3f} mm, its stated sigma {sigmas[i]:.3f} mm; "
            f"{rest[i]:.1f} % without it: place it again)")


def yaw_spread_deg(yaws_deg: ArrayLike) -> float:
    """How far apart the yaws lie on the half turn (a box turned 180 deg is the same box): 180
    minus the widest gap between neighbouring yaws taken modulo 180, degrees."""
    y = np.sort(_finite_1d(yaws_deg, "yaws") % 180.0)
    if y.size < 2:
        return 0.0
    gaps = np.diff(np.append(y, y[0] + 180.0))
    return float(180.0 - gaps.max())


def check_count(placements: int) -> None:
    """Refuse fewer than ``MIN_PLACEMENTS`` placements (InputError, saying why)."""
    if placements < MIN_PLACEMENTS:
        raise InputError(
            f"{placements} placements: a verification needs {MIN_PLACEMENTS} at least, the part "
            "placed at different positions and turned differently across the support"
        )


def check_placements(positions_mm: ArrayLike, yaws_deg: ArrayLike, board_size_mm: Sequence[float]) -> None:
    """Refuse placements too few, or not spread over the support, saying why.

    Parameters
    ----------
    positions_mm : array_like, shape (n, 2)
        Each placement's centre on the support, mm.
    yaws_deg : array_like, shape (n,)
        Each placement's yaw, degrees.
    board_size_mm : (float, float)
        The board's width and height, mm: the yardstick of the spread.

    Raises
    ------
    InputError
        Fewer than ``MIN_PLACEMENTS``; centres whose RMS distance from their mean is under
        ``MIN_SPREAD_SHARE`` of the board's diagonal; yaws spread over less than
        ``MIN_YAW_SPREAD_DEG`` on the half turn.
    """
    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 2)
    yaws = _finite_1d(yaws_deg, "yaws")
    if len(p) != yaws.size:
        raise InputError(f"{len(p)} positions but {yaws.size} yaws")
    check_count(len(p))
    spread = float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))
    diagonal = float(np.hypot(board_size_mm[0], board_size_mm[1]))
    if spread < MIN_SPREAD_SHARE * diagonal:
        raise InputError(
            f"the placements' centres lie {spread:.0f} mm (RMS) from their mean, under 1/8 of "
            f"the board's diagonal ({MIN_SPREAD_SHARE * diagonal:.0f} mm): place the part "
            "across the whole support"
        )
    turned = yaw_spread_deg(yaws)
    if turned < MIN_YAW_SPREAD_DEG:
        raise InputError(
            f"the placements' yaws span {turned:.0f} deg, under {MIN_YAW_SPREAD_DEG:g} deg: turn "
            "the part differently in each placement"
        )


def verify_placements(
    measured: ArrayLike,
    sigmas: ArrayLike,
    reference: Sequence[float],
    tolerance: float | None,
    *,
    positions_mm: ArrayLike,
    yaws_deg: ArrayLike,
    board_size_mm: Sequence[float],
    photos: Sequence[str],
    date: datetime,
) -> Verification:
    """A verification over the placements of one reference part.

    Parameters
    ----------
    measured, sigmas : array_like, shape (n, 3)
        Each placement's width, depth and height, and their stated one sigma, mm.
    reference : (float, float, float)
        The reference part's width >= depth, and height, mm.
    tolerance : float or None
        T of +-T, mm.
    positions_mm, yaws_deg, board_size_mm
        As ``check_placements``, which is applied first.
    photos : sequence of str
        The placements' names, n.
    date : datetime
        When the photos were measured (the caller's clock: the engine reads none).

    Raises
    ------
    InputError
        A reference or tolerance that is not positive, a reference whose width is under its depth,
        arrays of other shapes, or placements ``check_placements`` refuses.
    """
    ref = _finite_1d(reference, "reference")
    if ref.shape != (3,) or not np.all(ref > 0):
        raise InputError("the reference is its width, depth and height, each positive, mm")
    if ref[0] < ref[1]:
        raise InputError(
            f"the reference's width {ref[0]:g} is under its depth {ref[1]:g}: the station reports "
            "width >= depth (the footprint's longer side, then its shorter)"
        )
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance {tolerance:g}: expected T > 0 (mm, for +-T)")
    m = np.asarray(measured, dtype=np.float64)
    s = np.asarray(sigmas, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != 3 or s.shape != m.shape or len(photos) != len(m):
        raise InputError(
            f"expected ({len(photos)}, 3) measured values and sigmas, got {m.shape} and {s.shape}"
        )
    check_placements(positions_mm, yaws_deg, board_size_mm)
    dims = {
        name: verify_dimension(m[:, k], s[:, k], float(ref[k]), tolerance)
        for k, name in enumerate(DIMENSIONS)
    }
    decided = [f"{name}: {failure}" for name, d in dims.items() for failure in d.failures]
    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 2)
    return Verification(
        date=date,
        reference_mm={name: float(v) for name, v in zip(DIMENSIONS, ref, strict=True)},
        tolerance_mm=tolerance,
        photos=list(photos),
        positions_mm=[(float(x), float(y)) for x, y in p],
        yaws_deg=[float(v) for v in _finite_1d(yaws_deg, "yaws")],
        dimensions=dims,
        verified=not decided,
        decided_by=decided,
    )

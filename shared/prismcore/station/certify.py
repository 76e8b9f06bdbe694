"""What a station measurement says of the station itself: its verification's status, and how far
the camera moved since calibration (drift) and what that move may cost.

* Verification status (``verification_status``): "verified" (on its date, with each dimension's
  bias and repeatability), "not verified" (none stored, or the stored one failed), or "verified
  before the camera moved" (a verification stands, but the support has moved more than
  ``MOVED_PX`` in the photo since calibration, so its figures describe another geometry). Every
  status but "verified" carries a warning.
* Drift (``drift``): the re-registration's shift (the support's median move in the photo, px)
  and the same on the support, mm (where the calibrated view's pixels now fall on it). Its cost is
  what the move does to a dimension if the re-registration did not follow it exactly: the
  support's scale (mm per px) at the part's place in the photo, as calibrated against as now,
  times the dimension. Past a third of the tolerance (``COST_SHARE``) the measurement is warned
  and the station's re-verification asked for. The tolerance is the measurement's own (its
  ``tolerance_mm``), else the verification's, else three times the dimension's stated sigma (its
  own 3 sigma interval: then a move costing more than one sigma is warned).

Pure functions over the station, its registration of the photo and the measurement; and
``verify_station``, the reference part's photos measured and verified (the CLI and the API run it;
``verify_measured`` verifies placements already measured).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import datetime
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from prismcore.station.calibrate import PlanePose, Station
from prismcore.station.verify import DIMENSIONS, Verification

if TYPE_CHECKING:
    from prismcore.station.measure import StationMeasurement

__all__ = [
    "COST_SHARE",
    "MOVED_PX",
    "NOT_VERIFIED",
    "VERIFIED",
    "VERIFIED_BEFORE_MOVE",
    "drift",
    "mm_per_px",
    "parse_reference",
    "plane_homography",
    "verification_status",
    "verify_measured",
    "verify_station",
]

# The support moved further than this in the photo since calibration: the camera moved. Under it,
# vibration and the re-registration's own noise: renders turn the camera 1-3 px between the plate
# and a photo, and a still camera re-registers within 0.1 px.
MOVED_PX = 4.0
COST_SHARE = 1 / 3  # a drift costing more than this share of the tolerance is warned

VERIFIED = "verified"
NOT_VERIFIED = "not verified"
VERIFIED_BEFORE_MOVE = "verified before the camera moved"


def plane_homography(K: np.ndarray, pose: PlanePose) -> np.ndarray:
    """Support (x, y mm, z = 0) -> undistorted photo pixels, (3, 3)."""
    R, t = pose.rotation(), pose.translation()
    return cast("np.ndarray", K @ np.column_stack([R[:, 0], R[:, 1], t]))


def _apply(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    return cast("np.ndarray", p[:, :2] / p[:, 2:3])


def mm_per_px(H: np.ndarray, support_mm: np.ndarray) -> np.ndarray:
    """The support's scale, mm per px (the geometric mean over the two directions), at each of
    `support_mm` ((n, 2) points on the support) seen through `H` (support -> pixels)."""
    X = np.atleast_2d(np.asarray(support_mm, np.float64))
    # a degenerate pose (a station.json's plane through the camera) gives inf, not a warning:
    # the caller's finiteness check refuses it
    with np.errstate(all="ignore"):
        h = np.column_stack([X, np.ones(len(X))]) @ H.T
        w = h[:, 2]
        u, v = h[:, 0] / w, h[:, 1] / w
        # d(u, v)/d(x, y) of the projective map, px per mm
        j11 = (H[0, 0] - u * H[2, 0]) / w
        j12 = (H[0, 1] - u * H[2, 1]) / w
        j21 = (H[1, 0] - v * H[2, 0]) / w
        j22 = (H[1, 1] - v * H[2, 1]) / w
        return cast("np.ndarray", 1.0 / np.sqrt(np.abs(j11 * j22 - j12 * j21)))


def _tolerances(tolerance_mm: float | tuple[float, float, float] | None, verification: Verification | None,
                sigma: Mapping[str, float]) -> tuple[dict[str, float], str]:
    """Each dimension's T (of +-T) the drift is judged against, and where it came from."""
    if tolerance_mm is not None:
        if isinstance(tolerance_mm, (int, float)):
            return dict.fromkeys(DIMENSIONS, float(tolerance_mm)), "the measurement's tolerance"
        w, h, d = tolerance_mm  # the spec's order: width, height, depth
        return {"width": float(w), "height": float(h), "depth": float(d)}, "the measurement's tolerance"
    if verification is not None and verification.tolerance_mm is not None:
        return dict.fromkeys(DIMENSIONS, float(verification.tolerance_mm)), "the verification's tolerance"
    return {k: 3.0 * float(sigma[k]) for k in DIMENSIONS}, "3 sigma (no tolerance given)"


def drift(
    station: Station,
    homography: np.ndarray,
    shift_px: float,
    position_mm: tuple[float, float],
    dimensions: Mapping[str, float],
    sigma: Mapping[str, float],
    tolerance_mm: float | tuple[float, float, float] | None = None,
) -> dict[str, Any]:
    """How far the camera moved since calibration, and what it may cost a dimension.

    Parameters
    ----------
    station : Station
    homography : ndarray, (3, 3)
        The re-registration: the plate's (calibration's) undistorted pixels -> the photo's.
    shift_px : float
        The re-registration's shift, px (the support's median move in the photo).
    position_mm : (float, float)
        The part's footprint centre on the support.
    dimensions, sigma : mapping
        The part's width, depth and height and their one sigma, mm.
    tolerance_mm : float or (float, float, float) or None
        The measurement's T of +-T (one, or width, height, depth).

    Returns
    -------
    dict
        ``shift_px``, ``shift_mm`` (on the support), ``moved`` (over ``MOVED_PX``), ``cost_mm``
        and ``allowed_mm`` per dimension (a third of its tolerance), ``tolerance_from``,
        ``threshold_px`` (the shift whose cost reaches the allowance; None when the move costs
        nothing), ``reverify`` (a cost over its allowance).
    """
    K = station.camera.matrix()
    H_cal = plane_homography(K, station.plane)
    H_now = np.asarray(homography, np.float64) @ H_cal
    bw, bh = station.board.size_mm
    grid = np.array([[x, y] for x in np.linspace(0, bw, 5) for y in np.linspace(0, bh, 5)])
    # where each calibrated pixel of the board's area looks on the support now
    seen_now = _apply(np.linalg.inv(H_now), _apply(H_cal, grid))
    shift_mm = float(np.median(np.linalg.norm(seen_now - grid, axis=1)))
    part = np.array([position_mm], np.float64)
    pixel = _apply(H_now, part)
    # the same pixel read with the calibrated pose: the scale a measurement would take there
    scale_cal = float(mm_per_px(H_cal, _apply(np.linalg.inv(H_cal), pixel))[0])
    scale_now = float(mm_per_px(H_now, part)[0])
    relative = abs(scale_cal / scale_now - 1.0)
    tolerance, source = _tolerances(tolerance_mm, station.verification, sigma)
    cost = {k: relative * float(dimensions[k]) for k in DIMENSIONS}
    allowed = {k: COST_SHARE * tolerance[k] for k in DIMENSIONS}
    per_px = max(cost[k] / allowed[k] if allowed[k] > 0 else np.inf for k in DIMENSIONS)
    threshold = None if per_px == 0 or shift_px <= 0 else float(shift_px / per_px)
    return {
        "shift_px": round(float(shift_px), 2),
        "shift_mm": round(shift_mm, 2),
        "moved": bool(shift_px > MOVED_PX),
        "moved_over_px": MOVED_PX,
        "cost_mm": {k: round(v, 3) for k, v in cost.items()},
        "allowed_mm": {k: round(v, 3) for k, v in allowed.items()},
        "tolerance_from": source,
        "threshold_px": None if threshold is None or not np.isfinite(threshold) else round(threshold, 1),
        "reverify": bool(per_px > 1.0),
    }


def _figures(v: Verification) -> str:
    bias = " / ".join(f"{v.dimensions[k].bias_mm:+.2f}" for k in DIMENSIONS)
    rep = " / ".join(f"{v.dimensions[k].repeatability_mm:.2f}" for k in DIMENSIONS)
    return f"bias {bias} mm, repeatability {rep} mm (width / depth / height)"


def verification_status(verification: Verification | None, moved: bool, shift_px: float = 0.0,
                        shift_mm: float = 0.0) -> dict[str, Any]:
    """The station's verification as one measurement states it.

    Returns
    -------
    dict
        ``status`` (``VERIFIED``, ``NOT_VERIFIED`` or ``VERIFIED_BEFORE_MOVE``), ``date`` (ISO, or
        None), ``bias_mm`` and ``repeatability_mm`` per dimension (None without a verification),
        ``tolerance_mm``, ``text`` (the status in words) and ``warning`` (None when verified).
    """
    if verification is None:
        text = NOT_VERIFIED
        return {"status": NOT_VERIFIED, "date": None, "bias_mm": None, "repeatability_mm": None,
                "tolerance_mm": None, "text": text,
                "warning": "the station is not verified: its measurements are not checked against a "
                           "part of known size (prism station verify)"}
    day = f"{verification.date:%Y-%m-%d}"
    common = {
        "date": verification.date.isoformat(),
        "bias_mm": {k: round(verification.dimensions[k].bias_mm, 3) for k in DIMENSIONS},
        "repeatability_mm": {k: round(verification.dimensions[k].repeatability_mm, 3) for k in DIMENSIONS},
        "tolerance_mm": verification.tolerance_mm,
    }
    if not verification.verified:
        return {"status": NOT_VERIFIED, **common, "text": f"not verified (the verification on {day} failed)",
                "warning": f"the station is not verified: its verification on {day} failed "
                           f"({'; '.join(verification.decided_by)}); verify it again once mended"}
    figures = _figures(verification)
    if moved:
        return {"status": VERIFIED_BEFORE_MOVE, **common,
                "text": f"verified on {day} before the camera moved: {figures}",
                "warning": f"the station was verified on {day}, before the camera moved {shift_px:.1f} px "
                           f"({shift_mm:.1f} mm on the support) since calibration: its verification no "
                           "longer describes it; calibrate and verify it again"}
    return {"status": VERIFIED, **common, "text": f"verified on {day}: {figures}", "warning": None}


_NUMBER = r"\s*(\d+(?:\.\d*)?|\.\d+)\s*"


def parse_reference(text: str, name: str = "--reference") -> tuple[float, float, float]:
    """A reference part's size 'W,D,H' (mm) as three numbers; anything else is an InputError quoting it."""
    import re

    from prismcore.errors import InputError

    match = re.fullmatch(",".join([_NUMBER] * 3), text)
    if not match:
        raise InputError(
            f"{name} {text!r}: expected W,D,H in mm (width >= depth, then height), e.g. 70,45,30"
        )
    w, d, h = (float(v) for v in match.groups())
    return w, d, h


def verify_station(
    station: Station,
    photos: Sequence[tuple[str, np.ndarray]],
    reference: Sequence[float],
    tolerance: float | None,
    date: datetime,
) -> Verification:
    """Measure each (name, RGB photo) of the reference part on `station` and verify it
    (``verify_measured``): what `prism station verify` and the service's
    ``POST /v1/stations/{id}/verifications`` both run.

    Raises
    ------
    InputError
        Fewer than ``verify.MIN_PLACEMENTS`` photos, a photo the station cannot measure (its name
        first), or placements ``verify_measured`` refuses.
    """
    from prismcore.errors import InputError
    from prismcore.station.measure import measure_on_station
    from prismcore.station.verify import check_count

    check_count(len(photos))
    measured = []
    for name, photo in photos:
        try:
            measured.append((name, measure_on_station(photo, station)))
        except InputError as exc:
            raise InputError(f"{name}: {exc}") from None
    return verify_measured(station, measured, reference, tolerance, date)


def verify_measured(
    station: Station,
    measured: Sequence[tuple[str, StationMeasurement]],
    reference: Sequence[float],
    tolerance: float | None,
    date: datetime,
) -> Verification:
    """The verification (`verify.verify_placements`) of the reference part's placements, each
    (name, its measurement on `station`).

    Raises
    ------
    InputError
        A placement the station saw one side of only (one footprint side read on the top face,
        foreshortened: its error is the view's, not the station's; the user is told to turn the
        part, as the measurement's own warning says), or placements ``verify_placements`` refuses.
    """
    from prismcore.errors import InputError
    from prismcore.station.verify import verify_placements

    for name, m in measured:
        if m.top_only is not None:
            raise InputError(
                f"{name}: the station sees one side of the part only (its {m.top_only} read on the "
                "top face alone): turn the part so two of its sides face the camera, and photograph "
                "it again"
            )
    return verify_placements(
        [[m.dimensions[k] for k in DIMENSIONS] for _, m in measured],
        [[m.uncertainty[k] for k in DIMENSIONS] for _, m in measured],
        reference, tolerance,
        positions_mm=[m.position_mm for _, m in measured], yaws_deg=[m.yaw_deg for _, m in measured],
        board_size_mm=station.board.size_mm, photos=[name for name, _ in measured], date=date,
    )

"""The overlay of a scan from its report.json: which clicks and faces belong on which photo, the
legend's notes (dimensions with their uncertainty, focal length, fit RMS, method, frame), the
photo undistorted when the fit was; the drawing itself is `prismcore.outputs.overlay`. Its file
names (overlay.jpg by default, overlay.png on request) are `prismcore.outputs.writers.overlay_name`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from prismcore.errors import InputError
from prismcore.outputs.overlay import CORNER_OF, _as_rgb8, draw_overlay
from prismcore.report import Fit, ScanReport

__all__ = [
    "clicked_sides",
    "edge_use_notes",
    "given_dimension",
    "overlay_from_report",
    "photo_points",
    "points_found",
    "report_notes",
]

_SIDE_PHOTO_POINTS = ("p4", "p5", "p7")  # two-photo mode: the clicks made on the side photo
_DIMENSIONS = ("width", "height", "depth")


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def given_dimension(report: ScanReport) -> str | None:
    """The dimension the scale gave rather than measured: a known edge's (``inputs.scale`` of
    kind ``edge``), shown as "120.00 mm (given)", never as a measurement "± 0.00"."""
    if report.scale_source is not None:
        return None  # measured on a station (board): its height is only the derived points' scale
    scale = (report.inputs or {}).get("scale")
    if isinstance(scale, Mapping) and scale.get("kind") == "edge" and scale.get("edge") in _DIMENSIONS:
        return str(scale["edge"])
    return None


def points_found(report: ScanReport) -> str | None:
    """'points found (confidence 0.99)' when the zero-click search placed the points, else None."""
    if report.points_source != "auto":
        return None
    confidence = None if report.auto_points is None else _number(report.auto_points.confidence)
    return "points found" + (f" (confidence {confidence:.2f})" if confidence is not None else "")


def _points_key(report: ScanReport) -> str:
    """What the overlay's key calls the crosses: clicks, or points placed by the search or by a
    box fitted on a station (or a board), which nobody clicked."""
    if report.scale_source is not None:
        return "fitted box's point"
    return "found point" if points_found(report) else "click"


def report_notes(report: ScanReport) -> list[str]:
    """The legend's lines for a report: dimensions (± one standard deviation when the report
    has `uncertainty`; a known edge's "(given)"), focal length (`camera`), fit RMS (`fit`),
    method, video frame and points found by the search. Fields the report lacks are left out."""
    notes: list[str] = []
    dims = report.dimensions
    given = given_dimension(report)
    for name in _DIMENSIONS:
        value = _number(getattr(dims, name))
        if value is None:
            continue
        if name == given:
            notes.append(f"{name} {value:.2f} {dims.unit} (given)")
            continue
        sigma = None if report.uncertainty is None else _number(getattr(report.uncertainty, name))
        spread = f" ± {sigma:.2f}" if sigma is not None else ""
        notes.append(f"{name} {value:.2f}{spread} {dims.unit}".rstrip())
    camera = report.camera
    if camera is not None and (focal := _number(camera.focal_px)) is not None:
        notes.append(f"focal {focal:.0f} px ({camera.focal_source})")
    fit = report.fit
    if fit is not None and (rms := _number(fit.rms_px)) is not None:
        notes.append(f"fit RMS {rms:.2f} px")
    notes += edge_use_notes(fit)
    if report.method == "paper":
        notes.append("paper method (no perspective correction)")
    frame = report.frame
    if frame is not None:
        time_s = _number(frame.time_s)
        notes.append(f"frame {frame.index}" + (f" at {time_s:.2f} s" if time_s is not None else ""))
    if (found := points_found(report)) is not None:
        notes.append(found)
    return notes


def clicked_sides(fit: Fit | None, faces: Mapping[str, Any]) -> dict[str, list[int]]:
    """Per face drawn, the sides (0 top ... 3 left) the report's `fit.edges` says rest on the
    clicks; empty for a report without it."""
    edges = None if fit is None else fit.edges
    if edges is None:
        return {}
    return {face: [i for i, s in enumerate(edges[face][:4]) if s.used == "click"]
            for face in faces if face in edges}


def edge_use_notes(fit: Fit | None) -> list[str]:
    """Per face, which sides rest on the photo's edge and which on the clicks, and why each click
    side was kept (the report's `fit.edges`; nothing when the report has none)."""
    edges = None if fit is None else fit.edges
    if edges is None:
        return []
    notes = []
    for face, sides in edges.items():
        photo = [s.side for s in sides if s.used == "edge"]
        clicked = [s for s in sides if s.used == "click"]
        line = f"{face} edges: " + (f"{', '.join(photo)} from the photo" if photo else "none from the photo")
        whys: dict[str, list[str]] = {}
        for s in clicked:
            whys.setdefault(s.why, []).append(s.side)
        for why, names in whys.items():
            line += f"; {', '.join(names)} clicked ({why})"
        notes.append(line)
    return notes


def _residuals(fit: Fit | None) -> dict[str, float] | None:
    value = None if fit is None else fit.point_residuals_px
    if value is None:
        return None
    return {k: float(v) for k, v in value.items() if _number(v) is not None}


def _undistorted(
    image: np.ndarray, clicks: dict[str, Any], model: object
) -> tuple[np.ndarray, dict[str, Any]]:
    from pydantic import ValidationError

    from prismcore.camera import CameraModel, undistort_image, undistort_points

    if not isinstance(model, Mapping):
        raise InputError("the report says the photos were undistorted but has no inputs.camera")
    rgb = _as_rgb8(image)
    try:
        camera = CameraModel.model_validate(model).for_size(rgb.shape[1], rgb.shape[0])
    except ValidationError as exc:
        raise InputError("inputs.camera of the report is not a camera model: "
                         f"{exc.errors()[0]['msg']}") from None
    names = list(clicks)
    moved = (undistort_points(np.array([clicks[n] for n in names], np.float64), camera) if names
             else np.zeros((0, 2)))
    return undistort_image(rgb, camera), dict(zip(names, moved, strict=True))


def photo_points(two_photo: bool, photo: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The click names and face names that belong on `photo` ("front" or "side").

    Raises
    ------
    InputError
        `photo` is neither, or is "side" in single-photo mode.
    """
    if photo not in ("front", "side"):
        raise InputError(f"photo must be 'front' or 'side', got {photo!r}")
    if not two_photo:
        if photo == "side":
            raise InputError("photo 'side' asked of a single-photo report (it has no side photo)")
        return tuple(CORNER_OF), ("front", "side")
    if photo == "side":
        return _SIDE_PHOTO_POINTS, ("side",)
    return tuple(n for n in CORNER_OF if n not in _SIDE_PHOTO_POINTS), ("front",)


def overlay_from_report(image: np.ndarray, report: ScanReport, *, photo: str = "front",
                        warn_px: float = 3.0) -> np.ndarray:
    """The overlay of one photo of a scan, from the scan's report.json content.

    Reads ``inputs.points`` (the clicks), ``faces.<name>.corners`` (the fitted quads),
    ``warnings``, ``images`` (to check `image` is the photo meant) and, when present,
    ``fit.point_residuals_px`` (a mapping name -> px, or a list in the order of the clicks
    given), ``fit.rms_px``, ``uncertainty.<dimension>``, ``camera.focal_px`` and ``frame``.
    When ``camera.undistorted`` is true the fit is in the coordinates of the undistorted photo:
    the photo and the clicks are undistorted with ``inputs.camera`` first, and a note says so.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W), uint8 or float 0..255
        The photo `photo` of the scan (a video frame: the frame).
    report : ScanReport
        The report of the scan.
    photo : "front" or "side"
        Which photo `image` is; in two-photo mode each shows only its own clicks and face.
    warn_px : float
        See :func:`draw_overlay`.

    Returns
    -------
    ndarray, (H, W, 3) uint8 RGB

    Raises
    ------
    InputError
        The report lacks points or face corners, `image` is not the size the report says the
        photo has, or `photo` does not exist in this scan.
    """
    inputs = report.inputs or {}
    points = inputs.get("points")
    if not isinstance(points, Mapping):
        raise InputError("report has no inputs.points (the clicked reference points)")
    two_photo = bool(inputs.get("side_image"))
    names, face_names = photo_points(two_photo, photo)
    sizes = report.images or []
    index = 1 if photo == "side" else 0
    if len(sizes) > index:
        want = (sizes[index].width, sizes[index].height)
        got = (np.asarray(image).shape[1], np.asarray(image).shape[0])
        if want != got:
            raise InputError(f"the {photo} photo is {got[0]}x{got[1]} px but the report's is "
                             f"{want[0]}x{want[1]}")
    if report.faces is None:
        raise InputError("report has no faces")
    faces = {}
    for name in face_names:
        face = report.faces.get(name)
        if face is None:
            raise InputError(f"report has no corners for the {name} face")
        faces[name] = face.corners
    given = [n for n in CORNER_OF if points.get(n) is not None]
    clicks = {n: points[n] for n in given if n in names}
    notes = report_notes(report)
    if report.camera is not None and report.camera.undistorted:
        # the fit lives in the undistorted photo's coordinates: draw it there, clicks moved alike
        image, clicks = _undistorted(image, clicks, inputs.get("camera"))
        notes.append("drawn on the undistorted photo")
    residuals = _residuals(report.fit)
    if residuals is None and report.method == "paper":
        residuals = {}  # paper regions are axis-aligned boxes, not corners fitted to the clicks
    count = len(report.warnings)
    alerts = [f"{count} warning{'s' if count != 1 else ''} (see report.json)"] if count else []
    if not count:
        notes.append("no warnings")
    title = "PrismCloud fit" + (f" - {photo} photo" if two_photo else "")
    return draw_overlay(image, clicks, faces, residuals=residuals, notes=notes, alerts=alerts,
                        clicked_sides=clicked_sides(report.fit, faces),
                        title=title, warn_px=warn_px, side_face=report.side_face or "right",
                        points_key=_points_key(report))

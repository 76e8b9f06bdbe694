"""The measured part as the CAD outputs (`step`, `drawing`) see it: read from a scan's report.

Pure: a report dict in, a `Part` out; no file is read or written here.

The solid is the box ``[0, W] x [0, H] x [0, D]`` mm in its own frame (X along the width, Y along
the height, Z along the depth), and `Part.placement` carries it into the frame the measurement
knows:

* a photo (or a video frame): the box frame the cloud files are in, so the solid and the cloud
  line up in a CAD program: the origin is P1 (the front face's upper-left corner), X along
  P1 -> P2, Y down the front face, Z into the part. The placement is the identity.
* a station or a board (the report's ``station`` block, ``scale_source`` "station" or "board"):
  the board's frame (x, y on the support, z = 0 on it and pointing into it, so the part stands at
  z from -H to 0), with the footprint's centre at ``station.position_mm`` and the width along
  ``station.yaw_deg`` from the frame's x axis: parts measured on one station line up. The box's
  corner at its own origin is a footprint corner on the support; its Y (the height) points up,
  -z.

A scan without a scale is refused (`InputError`): its dimensions are pixels, and a solid or a
drawing in pixels means nothing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Any

from prismcore.errors import InputError

__all__ = ["AXES", "Dimension", "Part", "dimension_text", "part_from_report", "scale_source_text"]

AXES = {"width": "X", "height": "Y", "depth": "Z"}
"""Each dimension's axis in the solid's own frame."""

Matrix = tuple[tuple[float, float, float, float], tuple[float, float, float, float],
               tuple[float, float, float, float]]
"""A rigid transform as its 3 x 4 matrix [R | t] (row-major): x' = R x + t."""

_IDENTITY: Matrix = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0))


@dataclass(frozen=True)
class Dimension:
    """One measured dimension: its value and one standard deviation (mm, None when unknown),
    and against a nominal size its tolerance, deviation and verdict (None without one)."""

    name: str
    value_mm: float
    sigma_mm: float | None
    nominal_mm: float | None = None
    tolerance_mm: float | None = None
    deviation_mm: float | None = None
    verdict: str | None = None

    @property
    def axis(self) -> str:
        return AXES[self.name]


@dataclass(frozen=True)
class Part:
    """What a CAD output says of the part: its three dimensions, the part's verdict (None
    without a nominal), the transform from its own frame into `frame`, the photo's name, where
    the scale came from, and the k of the verdicts' interval."""

    dimensions: tuple[Dimension, Dimension, Dimension]
    verdict: str | None
    frame: str
    frame_text: str
    placement: Matrix
    photo: str
    scale_source: str
    k: float | None
    engine_version: str

    def dimension(self, name: str) -> Dimension:
        return next(d for d in self.dimensions if d.name == name)

    @property
    def size(self) -> tuple[float, float, float]:
        """(W, H, D) mm."""
        w, h, d = (self.dimension(n).value_mm for n in ("width", "height", "depth"))
        return w, h, d


def dimension_text(d: Dimension) -> str:
    """How every CAD output writes a dimension: value ± one sigma, mm to 3 decimals, and the
    verdict when there is one (``120.012 ± 1.008 pass``)."""
    text = f"{d.value_mm:.3f}" + ("" if d.sigma_mm is None else f" ± {d.sigma_mm:.3f}")
    return text + (f" {d.verdict}" if d.verdict else "")


def part_from_report(report: Mapping[str, Any], what: str = "the CAD outputs") -> Part:
    """The part a scan's `report` (report.json's dict) measured.

    Raises
    ------
    InputError
        The report's dimensions are not in mm (no scale: pixels), or are missing or not positive.
    """
    dims = report.get("dimensions") or {}
    unit = dims.get("unit")
    if unit != "mm":
        raise InputError(f"{what} need the dimensions in mm, but this scan's are in {unit or 'no unit'} "
                         "(no scale): a solid or a drawing in pixels means nothing; give a scale "
                         "(mm_per_px, a pinhole distance, a known edge) or measure on a station")
    sigma = report.get("uncertainty") or {}
    quality = report.get("quality") or {}
    judged = quality.get("dimensions") or {}
    out = []
    for name in ("width", "height", "depth"):
        value = dims.get(name)
        if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
            raise InputError(f"{what} need a positive {name}, got {value!r}")
        s = sigma.get(name)
        q = judged.get(name) or {}
        out.append(Dimension(name, float(value), None if s is None else float(s),
                             _float(q.get("nominal_mm")), _float(q.get("tolerance_mm")),
                             _float(q.get("deviation_mm")), q.get("verdict")))
    frame, frame_text, placement = _placement(report)
    k = quality.get("k")
    return Part(dimensions=(out[0], out[1], out[2]), verdict=quality.get("verdict"), frame=frame,
                frame_text=frame_text, placement=placement, photo=_photo(report),
                scale_source=scale_source_text(report), k=None if k is None else float(k),
                engine_version=str(report.get("engine_version", "")))


def _float(v: Any) -> float | None:
    return None if v is None else float(v)


def _placement(report: Mapping[str, Any]) -> tuple[str, str, Matrix]:
    station = report.get("station") or {}
    position, yaw = station.get("position_mm"), station.get("yaw_deg")
    if position is None or yaw is None:
        return ("box", "the box frame of the cloud files: origin P1 (front face, upper left), X along "
                "P1->P2 (width), Y down the front face (height), Z into the part (depth)", _IDENTITY)
    source = str(report.get("scale_source") or "station")
    w, _, d = (float(report["dimensions"][n]) for n in ("width", "height", "depth"))
    a = math.radians(float(yaw))
    c, s = math.cos(a), math.sin(a)
    x0, y0 = float(position[0]), float(position[1])
    # The box's own X (width) along the yaw, its Z (depth) across it on the support, its Y
    # (height) up, which is -z in the board's frame: [X Y Z] -> columns (c, s, 0), (0, 0, -1),
    # (-s, c, 0), a proper rotation. Its own origin is the footprint corner at (-W/2, -D/2).
    tx = x0 - c * w / 2 + s * d / 2
    ty = y0 - s * w / 2 - c * d / 2
    matrix: Matrix = ((c, 0.0, -s, tx), (s, 0.0, c, ty), (0.0, -1.0, 0.0, 0.0))
    return (source, f"the {source}'s frame (the board's: x, y on the support, z = 0 on it and "
            f"pointing into it, so the part stands at z from -H to 0): footprint centre "
            f"({x0:g}, {y0:g}) mm, width at {float(yaw):g} deg from x", matrix)


def _photo(report: Mapping[str, Any]) -> str:
    views = report.get("views")
    if isinstance(views, list) and views:  # a joint fit's: the views used
        names = [str(v.get("name") or v.get("index")) for v in views]
        return f"{len(names)} views: " + ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
    inputs = report.get("inputs") or {}
    image = str(inputs.get("image") or "photo")
    name = PurePosixPath(image.replace("\\", "/")).name or image
    frame = report.get("frame") or {}
    if frame.get("index") is not None:
        name += f", frame {frame['index']}"
    return name


def scale_source_text(report: Mapping[str, Any]) -> str:
    """Where the scan's millimetres came from, in words (for the drawing and the STEP header)."""
    source = report.get("scale_source")
    if source == "station":
        return "station calibration (the support plane and plate)"
    if source == "board":
        return "the board in the photo"
    scale = (report.get("inputs") or {}).get("scale") or {}
    camera = report.get("camera") or {}
    kind = scale.get("kind")
    if kind == "mm_per_px":
        return f"given {scale.get('front')} mm per px"
    if kind == "edge":
        return f"known edge: {scale.get('edge')} = {scale.get('length_mm')} mm"
    if kind == "pinhole":
        focal = camera.get("focal_px")
        focal_text = "" if focal is None else f", focal {focal:.1f} px ({camera.get('focal_source')})"
        return f"pinhole: distance {scale.get('distance_mm')} mm{focal_text}"
    return str(source or kind or "unknown")

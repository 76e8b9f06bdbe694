"""The job specification of one scan: the model the CLI reads from `--spec` and the API accepts.

Image references are plain strings here: the CLI reads them as file paths (relative to the spec
file), the service as object-store, upload or URL references. Everything the engine needs
besides the pixels is in this model, so a spec plus its images fully determines the output.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, PositiveFloat, model_validator

__all__ = [
    "FILE_NAMES",
    "KnownEdge",
    "MmPerPx",
    "Pinhole",
    "Point",
    "ReferencePoints",
    "Scale",
    "ScanSpec",
    "parse_points",
]

Point = tuple[FiniteFloat, FiniteFloat]
"""An image position (x, y) in pixels: x = column, y = row, origin at the image's top-left
pixel centre."""

FILE_NAMES = {"csv": "cloud.csv", "ply": "cloud.ply", "report": "report.json"}
"""The file name of each output kind, the same in the CLI's folders and the service's keys
(here, not in writers, so the API can use it without loading numpy)."""

_POINT_NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ReferencePoints(_Strict):
    """The paper's five reference points, plus two optional extra corners.

    p1 front upper-left, p2 front upper-right, p3 front lower-right, p4 side upper-left,
    p5 side upper-right; p6 front lower-left and p7 side lower-right make each face a full
    quadrilateral, which perspective correction needs.
    """

    p1: Point
    p2: Point
    p3: Point
    p4: Point
    p5: Point
    p6: Point | None = None
    p7: Point | None = None

    @model_validator(mode="before")
    @classmethod
    def _from_list(cls, data: object) -> object:
        # A bare list [[x1, y1], ..., [x5, y5], ([x6, y6], [x7, y7])] is accepted too.
        if isinstance(data, list | tuple):
            if len(data) not in (5, 7):
                raise ValueError(f"give 5 or 7 points, got {len(data)}")
            return dict(zip(_POINT_NAMES, data, strict=False))
        return data

    def as_dict(self) -> dict[str, Point]:
        return {n: getattr(self, n) for n in _POINT_NAMES if getattr(self, n) is not None}


class MmPerPx(_Strict):
    """Millimetres per pixel in the face plane; `side` is the side photo's (two-photo mode)."""

    kind: Literal["mm_per_px"] = "mm_per_px"
    front: PositiveFloat
    side: PositiveFloat | None = None


class Pinhole(_Strict):
    """Shooting distance: depth of the photographed face's centre along the optical axis, mm.

    Needs `focal_px` in the spec. For a face photographed squarely this gives
    mm-per-pixel = distance / focal.
    """

    kind: Literal["pinhole"] = "pinhole"
    distance_mm: PositiveFloat
    side_distance_mm: PositiveFloat | None = None


class KnownEdge(_Strict):
    """One real edge length of the part."""

    kind: Literal["edge"] = "edge"
    edge: Literal["width", "height", "depth"] = "width"
    length_mm: PositiveFloat


Scale = Annotated[MmPerPx | Pinhole | KnownEdge, Field(discriminator="kind")]


class CsvOptions(_Strict):
    """CSV layout. The default (bare `x,y,z` rows) is the paper's and what CAD importers read."""

    header: bool = False
    colors: bool = False


class ScanSpec(_Strict):
    """Everything needed to turn one photo (or a front and a side photo) into a point cloud."""

    image: str = Field(min_length=1, description="Front photo (single-photo mode: the only one).")
    side_image: str | None = Field(
        default=None, description="Side photo; when given, p4, p5 and p7 refer to it."
    )
    points: ReferencePoints
    tolerance: float = Field(default=12.0, ge=0.0, le=128.0, description="RGB tolerance per channel.")
    method: Literal["default", "paper"] = "default"
    scale: Scale | None = None
    focal_px: PositiveFloat | None = Field(
        default=None, description="Focal length in pixels; with p6 and p7 it corrects perspective."
    )
    principal_point: Point | None = Field(
        default=None, description="Optical centre (x, y) in pixels; the image centre if omitted."
    )
    cloud: Literal["surface", "volume"] = "surface"
    formats: list[Literal["csv", "ply"]] = Field(default_factory=lambda: ["csv", "ply"], min_length=1)
    csv: CsvOptions = CsvOptions()
    ply_ascii: bool = False
    max_pixels: int = Field(default=50_000_000, gt=0, description="Refuse larger images.")
    max_points: int = Field(default=20_000_000, gt=0, description="Refuse larger clouds.")

    @model_validator(mode="after")
    def _pinhole_needs_focal(self) -> ScanSpec:
        if isinstance(self.scale, Pinhole) and self.focal_px is None:
            raise ValueError("a shooting distance needs focal_px (the focal length in pixels)")
        return self

    @property
    def two_photo(self) -> bool:
        return self.side_image is not None


_PAIR = re.compile(r"^\s*(-?\d+(?:\.\d+)?)\s*,\s*(-?\d+(?:\.\d+)?)\s*$")


def parse_points(text: str) -> ReferencePoints:
    """Parse ``"x1,y1 x2,y2 x3,y3 x4,y4 x5,y5 [x6,y6 x7,y7]"`` into reference points.

    Raises
    ------
    ValueError
        If a pair is malformed or the count is not 5 or 7; the message quotes the bad text.
    """
    pairs = text.split()
    points = []
    for pair in pairs:
        match = _PAIR.match(pair)
        if match is None:
            raise ValueError(f"bad point {pair!r}: expected x,y")
        points.append((float(match[1]), float(match[2])))
    if len(points) not in (5, 7):
        raise ValueError(f"expected 5 or 7 points (P1..P5 [P6 P7]), got {len(points)} in {text!r}")
    return ReferencePoints.model_validate(points)

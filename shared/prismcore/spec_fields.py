"""The parts a job spec (`prismcore.spec.ScanSpec`) is made of: reference points and how they are
parsed, the scales, the CSV options, a video's frame selection, where the zero-click search
looks, and the output files' names (the format table's, `prismcore.formats`). Pydantic only,
like `prismcore.spec` (no numpy, no OpenCV).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Sequence
from typing import Annotated, Any, Literal, Protocol, get_args

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    FiniteFloat,
    NonNegativeInt,
    ValidationError,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from prismcore.bounds import MmPerPxValue, PositiveMm
from prismcore.formats import FILE_NAMES, FORMATS, METRIC_FORMATS, PART_FORMATS, OutputFormat, output_files

__all__ = [
    "FILE_NAMES",
    "FORMATS",
    "ITEM_KINDS",
    "JOINT_MAX_PIXELS",
    "JOINT_MAX_VIEWS",
    "JOINT_NAME",
    "METRIC_FORMATS",
    "PART_FORMATS",
    "SUMMARY_NAME",
    "TRACKED_NAME",
    "AutoPoints",
    "CsvOptions",
    "FrameSelection",
    "ItemKind",
    "KnownEdge",
    "MmPerPx",
    "OutputFormat",
    "Pinhole",
    "Point",
    "ReferencePoints",
    "Scale",
    "Seconds",
    "SideFace",
    "error_message",
    "frame_folder",
    "item_kind",
    "output_files",
    "parse_points",
    "scan_spec_rules",
    "search_area_problem",
]


Point = tuple[FiniteFloat, FiniteFloat]
"""An image position (x, y) in pixels: x = column, y = row, origin at the image's top-left
pixel centre."""

SUMMARY_NAME = "summary.json"
"""The file name of a video job's summary across its frames (beside the frames' folders)."""

JOINT_NAME = FILE_NAMES["joint"]
"""The file name of a joint fit's report (several views of one part measured as ONE box)."""

TRACKED_NAME = FILE_NAMES["tracked_points"]
"""The file name of the points tracked from one frame of a video to the others (points_frame):
per frame its seven points and their quality, or the reason it is left out."""

JOINT_MAX_VIEWS = 24
"""The most views (photos, or a video's frames) one joint fit measures together: they are held
decoded at once, and the fit's outlier test refits once per view."""

JOINT_MAX_PIXELS = 150_000_000
"""The most pixels a joint fit's views hold together (12 photos of 12 megapixels): all are held
decoded at once (24 views of 12 MP held 1.3 GB), and a worker process has a share of a pod's
memory."""


def frame_folder(index: int) -> str:
    """The folder (CLI) or key prefix (service) of one frame's outputs: ``frame_000123``."""
    return f"frame_{index:06d}"


_POINT_NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ReferencePoints(_Strict):
    """The paper's five reference points, plus two optional extra corners.

    p1 front upper-left, p2 front upper-right, p3 front lower-right, p6 front lower-left.
    p4, p5 and p7 mark the second face by role: p4 the front corner where the second face's top
    (far) edge starts, p5 the second face's far corner next to p4, p7 its far corner next to
    the other shared corner. A right side (the paper's; a side photo's): p4 = p2 (side
    upper-left), p5 side upper-right, p7 side lower-right. In one photo also a left side:
    p4 = p1, p5 the side's far upper corner (left of p1), p7 its far lower corner (left of p6);
    or the top: p4 = p1, p5 the top's far corner above p1, p7 its far corner above p2 (see
    `ScanSpec.side_face`). p6 and p7 make each face a full quadrilateral, which perspective
    correction needs.
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


def _kind_required(schema: dict[str, Any]) -> None:
    # `kind` tells the three scales apart (Scale's discriminator): a scale without it is refused,
    # so the published schema requires it, though the models default it for code building one.
    schema["required"] = ["kind", *schema.get("required", [])]


class MmPerPx(_Strict):
    """Millimetres per pixel in the face plane; `side` is the side photo's (two-photo mode)."""

    model_config = ConfigDict(json_schema_extra=_kind_required)

    kind: Literal["mm_per_px"] = "mm_per_px"
    front: MmPerPxValue
    side: MmPerPxValue | None = None


class Pinhole(_Strict):
    """Shooting distance: depth of the photographed face's centre along the optical axis, mm.

    Needs `focal_px` in the spec. For a face photographed squarely this gives
    mm-per-pixel = distance / focal.
    """

    model_config = ConfigDict(json_schema_extra=_kind_required)

    kind: Literal["pinhole"] = "pinhole"
    distance_mm: PositiveMm
    side_distance_mm: PositiveMm | None = None


class KnownEdge(_Strict):
    """One real edge length of the part."""

    model_config = ConfigDict(json_schema_extra=_kind_required)

    kind: Literal["edge"] = "edge"
    edge: Literal["width", "height", "depth"] = "width"
    length_mm: PositiveMm


Scale = Annotated[MmPerPx | Pinhole | KnownEdge, Field(discriminator="kind")]


class CsvOptions(_Strict):
    """CSV layout. The default (bare `x,y,z` rows) is the paper's and what CAD importers read."""

    header: bool = False
    colors: bool = False


Seconds = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class FrameSelection(_Strict):
    """Which frames of a video to measure.

    Either `indices` alone, or any of `start_s`/`end_s`, `every` and `sharpest` together: the
    candidates are the frames whose time (index / fps) lies in [start_s, end_s), every
    `every`-th of them counted from the first; `sharpest` then keeps the K candidates with the
    highest variance of the Laplacian (the least blurred). An empty selection means every frame.
    The number of frames measured is capped by the caller (the service's setting, the CLI's
    ``--max-frames``).
    """

    model_config = ConfigDict(json_schema_extra=lambda schema: _frame_selection_schema(schema))

    every: int | None = Field(default=None, ge=1, description="Every Nth candidate frame (1: all).")
    start_s: Seconds | None = Field(default=None, description="First time measured, seconds.")
    end_s: Seconds | None = Field(default=None, description="Frames before this time, seconds.")
    indices: list[NonNegativeInt] | None = Field(
        default=None, min_length=1, description="Explicit frame indices (0 = the first frame)."
    )
    sharpest: int | None = Field(
        default=None, ge=1, description="Keep the K sharpest candidates (variance of the Laplacian)."
    )

    @model_validator(mode="after")
    def _consistent(self) -> FrameSelection:
        if self.indices is not None:
            others = {k: getattr(self, k) for k in ("every", "start_s", "end_s", "sharpest")
                      if getattr(self, k) is not None}
            if others:
                given = ", ".join(f"{k}={v!r}" for k, v in others.items())
                raise ValueError(f"indices name the frames themselves: drop {given}")
            repeated = sorted(i for i, n in Counter(self.indices).items() if n > 1)
            if repeated:
                raise ValueError(f"frame indices repeated: {repeated}")
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise ValueError(f"end_s {self.end_s!r} must be after start_s {self.start_s!r}")
        return self


class AutoPoints(_Strict):
    """Where the zero-click search looks: the box around `hint`, or inside `roi`."""

    hint: Point | None = Field(default=None, description="(x, y) px on the box wanted (a video: in "
                               "its first selected frame; each later frame starts at the box the "
                               "frame before showed).")
    roi: tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat] | None = Field(
        default=None, description="(x0, y0, x1, y1) px: look for the box inside this region only.")


def search_area_problem(hint: tuple[float, float] | None, roi: tuple[float, float, float, float] | None,
                        width: int, height: int) -> tuple[str, str] | None:
    """Why the zero-click search cannot look where it is told in a `width` x `height` px photo:
    ("hint" or "roi", the reason), or None. One rule for the engine (`locate.find_points`) and
    the API (at submit, where the upload's size is known)."""
    w, h = width, height
    if hint is not None:
        hx, hy = (float(v) for v in hint)
        if not (math.isfinite(hx) and math.isfinite(hy) and 0 <= hx < w and 0 <= hy < h):
            return "hint", f"hint {hint!r} is outside the {w}x{h} image"
    if roi is not None:
        x0, y0, x1, y1 = (float(v) for v in roi)
        if not all(math.isfinite(v) for v in (x0, y0, x1, y1)) or x1 <= x0 or y1 <= y0:
            return "roi", f"roi {roi!r}: expected X0,Y0,X1,Y1 with X0 < X1 and Y0 < Y1"
        ix0, iy0 = max(0, math.floor(x0)), max(0, math.floor(y0))
        ix1, iy1 = min(w, math.ceil(x1) + 1), min(h, math.ceil(y1) + 1)
        if ix1 - ix0 < 16 or iy1 - iy0 < 16:
            return "roi", f"roi {roi!r} leaves less than 16x16 px of the {w}x{h} image"
    return None


SideFace = Literal["auto", "right", "left", "top"]


def error_message(msg: str) -> str:
    """A spec validation error's message as a user reads it: pydantic's "Value error, " before a
    validator's own message says nothing to a user (the CLI's one line and the API's problem
    details both show it through here)."""
    return msg.removeprefix("Value error, ")


def _field_error(loc: tuple[str | int, ...], message: str, value: object) -> ValidationError:
    """A validation error at `loc` inside the model being validated (pydantic prefixes the
    model's own place), so a cross-field rule points at the field at fault."""
    return ValidationError.from_exception_data("ScanSpec", [InitErrorDetails(
        type=PydanticCustomError("value_error", "{message}", {"message": message}), loc=loc,
        input=value)])


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


# -- ScanSpec's rules across fields, stated in its published JSON Schema ---------------------------
# ScanSpec's validators refuse combinations a field alone cannot (a station with points, views
# with a cloud option, a nominal without its tolerance...). The commonest are stated here as
# JSON Schema (`allOf` of if/then), so a client or a fuzzer knows what is taken; each mirrors a
# check of ScanSpec._consistent and must stay as exact (tests/service/test_schemathesis.py holds
# the API to both). Left to the validators, and named in that test: what depends on the files
# named (points inside the photo, frames within the video, a stored station), what compares
# numbers (a region's corners, frame_points' keys against frames.indices), and the rules a
# fuzzer's generator could no longer canonicalize on top of these (each if/then doubles its
# work; Schemathesis 4.32 gives up past about ten): a shooting distance without a focal length,
# side_face left or top with side_image, frames with side_image, points_frame's needs, fit
# "frames" without frames, and fit "joint"'s frame_points and options.

_SEVEN = {"type": "object", "required": ["p6", "p7"],
          "properties": {"p6": {"type": "array"}, "p7": {"type": "array"}}}
_CLOUD_DEFAULTS = {"tolerance": {"const": 12.0}, "ply_ascii": {"const": False},
                   "max_points": {"const": 20_000_000},
                   "csv": {"properties": {"header": {"const": False}, "colors": {"const": False}}}}


def _given(name: str) -> dict[str, Any]:
    """`name` is in the body and not null (null is "not given")."""
    return {"required": [name], "properties": {name: {"not": {"type": "null"}}}}


def _unset(*names: str, **also: Any) -> dict[str, Any]:
    """Each of `names` left out or null; each of `also` left out or as its schema says."""
    return {"properties": {**{n: {"type": "null"} for n in names}, **also}}


def _is(name: str, value: Any) -> dict[str, Any]:
    return {"required": [name], "properties": {name: {"const": value}}}


def _kind(kind: str) -> dict[str, Any]:
    scale = {"type": "object", "required": ["kind"], "properties": {"kind": {"const": kind}}}
    return {"required": ["scale"], "properties": {"scale": scale}}


def _rule(when: dict[str, Any], then: dict[str, Any]) -> dict[str, Any]:
    return {"if": when, "then": then}


def _all(*clauses: dict[str, Any]) -> dict[str, Any]:
    return {"allOf": list(clauses)}


def _any(*clauses: dict[str, Any]) -> dict[str, Any]:
    return {"anyOf": list(clauses)}


def _frame_selection_schema(schema: dict[str, Any]) -> None:
    # FrameSelection._consistent: indices alone, each once (end_s after start_s compares numbers)
    schema["allOf"] = [_rule(_given("indices"), _unset("every", "start_s", "end_s", "sharpest"))]
    for option in schema["properties"]["indices"].get("anyOf", []):
        if option.get("type") == "array":
            option["uniqueItems"] = True


def scan_spec_rules() -> list[dict[str, Any]]:
    """ScanSpec's cross-field rules as JSON Schema clauses (its schema's `allOf`)."""
    auto = _any(_is("points", "auto"), _given("auto_points"))
    metric = {"required": ["formats"],
              "properties": {"formats": {"contains": {"enum": list(METRIC_FORMATS)}}}}
    # a joint fit makes no cloud: the cloud's options at their defaults, formats the part's or the default
    formats = _any({"items": {"enum": list(PART_FORMATS)}},
                   {"items": {"enum": ["csv", "ply"]},
                    "allOf": [{"contains": {"const": "csv"}}, {"contains": {"const": "ply"}}]})
    no_cloud = _unset(method={"const": "default"}, cloud={"const": "surface"}, formats=formats,
                      **_CLOUD_DEFAULTS)
    need_scale = _any(_given("scale"), _given("station"))
    # In this order: Schemathesis' generator canonicalizes the clauses one after another, within a
    # budget that another order of the same clauses runs past (tests/service/test_schemathesis.py).
    return [
        # _station_consistent: the photo alone
        _rule(_given("station"), _unset("points", "auto_points", "frame_points", "frames", "views", "fit",
                                        "side_image", "scale", "focal_px", "principal_point", "camera",
                                        side_face={"const": "auto"}, method={"const": "default"})),
        # nominal and tolerance_mm together
        _rule(_given("nominal"), _given("tolerance_mm")),
        _rule(_given("tolerance_mm"), _given("nominal")),
        # points per frame, or the same points (or "auto") for every frame
        _rule(_given("frame_points"), _unset("points", "auto_points")),
        # what is in mm needs a scale (or a station): one clause a field (an `anyOf` in `if` is
        # past what the generator canonicalizes beside the others)
        _rule(metric, need_scale),
        # _joint_consistent: one known edge
        _rule(_any(_given("views"), _is("fit", "joint")), _kind("edge")),
        _rule(_given("nominal"), need_scale),
        _rule(_given("spacing_mm"), need_scale),
        # views carry their own points and make no cloud
        _rule(_given("views"), _all(
            _unset("points", "auto_points", "frame_points", "frames", "side_image", "camera",
                   "principal_point", "spacing_mm", side_face={"const": "auto"},
                   fit=_any({"const": "joint"}, {"type": "null"})),
            no_cloud)),
        # "auto" is for one photo (or a video's frames), and finds the second face itself
        _rule(auto, _unset("side_image", points=_any({"const": "auto"}, {"type": "null"}),
                           side_face={"const": "auto"})),
    ]


ItemKind = Literal["photo", "found", "video", "tracked", "tracked_joint", "frames_joint", "views",
                   "station"]
"""What a job item is, which decides what measures it (`ScanSpec.kind`): one photo (or a front and
a side photo) with clicked points; one photo whose points are found (points "auto"); a video's
frames, each measured as a photo (`frames`, clicked points, frame_points or "auto"); a video's
frames with points tracked from `points_frame`; those tracked frames measured as one box (fit
"joint"); a video's frames of `frame_points` measured as one box (fit "joint"); several photos
measured as one box (`views`); a photo measured on a stored station (`station`)."""

ITEM_KINDS: tuple[ItemKind, ...] = get_args(ItemKind)
"""Every item kind: each caller's table of kinds names them all (tests check it)."""


class _KindFields(Protocol):
    """The fields of a spec that its kind is read from."""

    @property
    def views(self) -> Sequence[object] | None: ...
    @property
    def station(self) -> str | None: ...
    @property
    def fit(self) -> str | None: ...
    @property
    def points_frame(self) -> int | None: ...
    @property
    def frames(self) -> object | None: ...
    @property
    def auto_points(self) -> object | None: ...


def item_kind(spec: _KindFields) -> ItemKind:
    """The kind of a valid spec's item. The spec's rules leave one kind to each valid spec (a
    station or views go with no frames, points or fit "frames"; points_frame needs frames), and
    the tests are made in this order so that every caller's earlier order gives the same."""
    if spec.views is not None:
        return "views"
    if spec.station is not None:
        return "station"
    if spec.fit == "joint":
        return "tracked_joint" if spec.points_frame is not None else "frames_joint"
    if spec.points_frame is not None:
        return "tracked"
    if spec.frames is not None:
        return "video"
    return "found" if spec.auto_points is not None else "photo"

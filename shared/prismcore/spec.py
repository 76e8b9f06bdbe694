"""The job specification of one scan: the model the CLI reads from `--spec` and the API accepts.

Image references are plain strings here: the CLI reads them as file paths (relative to the spec
file), the service as object-store, upload or URL references. Everything the engine needs
besides the pixels is in this model, so a spec plus its images fully determines the output.
A spec with `frames` names a video: each selected frame is measured as a photo of its own.
The parts it is made of (points, scales, frame selection, file names) are `prismcore.spec_fields`,
whose public names this module names too.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import (
    BeforeValidator,
    ConfigDict,
    Field,
    NonNegativeInt,
    field_validator,
    model_validator,
)

from prismcore.bounds import FocalPx, NonNegativeMm, PositiveMm
from prismcore.camera import CameraModel
from prismcore.spec_fields import (
    FILE_NAMES,
    FORMATS,
    JOINT_MAX_PIXELS,
    JOINT_MAX_VIEWS,
    JOINT_NAME,
    METRIC_FORMATS,
    PART_FORMATS,
    SUMMARY_NAME,
    TRACKED_NAME,
    AutoPoints,
    CsvOptions,
    FrameSelection,
    ItemKind,
    KnownEdge,
    MmPerPx,
    OutputFormat,
    Pinhole,
    Point,
    ReferencePoints,
    Scale,
    SideFace,
    _field_error,
    _Strict,
    error_message,
    frame_folder,
    item_kind,
    output_files,
    parse_points,
    scan_spec_rules,
    search_area_problem,
)

__all__ = [
    "FILE_NAMES",
    "FORMATS",
    "JOINT_MAX_PIXELS",
    "JOINT_MAX_VIEWS",
    "JOINT_NAME",
    "METRIC_FORMATS",
    "PART_FORMATS",
    "SUMMARY_NAME",
    "TRACKED_NAME",
    "AutoPoints",
    "FrameSelection",
    "ItemKind",
    "KnownEdge",
    "MmPerPx",
    "OutputFormat",
    "Pinhole",
    "Point",
    "ReferencePoints",
    "Scale",
    "ScanSpec",
    "SideFace",
    "ViewSpec",
    "error_message",
    "frame_folder",
    "output_files",
    "parse_points",
    "search_area_problem",
    "view_spec",
]


_DEFAULT_FORMATS: tuple[OutputFormat, ...] = ("csv", "ply")


def _spec_schema(schema: dict[str, Any]) -> None:
    schema["required"] = [n for n in schema.get("required", []) if n != "image"]
    if not schema["required"]:
        del schema["required"]
    # Each way of giving the points, the field given and not null (null is "not given"); a
    # station item has none, the station finds the part.
    # Titled: a generated client names each way after its title (ScanWithPoints, not ScanSpecType0).
    ways = {"points": "ScanWithPoints", "frame_points": "ScanWithFramePoints", "views": "ScanWithViews",
            "station": "ScanOnStation", "auto_points": "ScanWithAutoPoints"}
    schema["anyOf"] = [{"title": title, "required": ["image", name] if name != "views" else [name],
                        "properties": {name: {"not": {"type": "null"}}}}
                       for name, title in ways.items()]
    schema["allOf"] = scan_spec_rules()


def _views_schema(schema: dict[str, Any]) -> None:
    # The count _joint_consistent holds views to, stated where a client (or a fuzzer) reads it.
    for option in schema.get("anyOf", []):
        if option.get("type") == "array":
            option.update(minItems=2, maxItems=JOINT_MAX_VIEWS)


def _seven_points_schema(schema: dict[str, Any]) -> None:
    # A view's points are ReferencePoints with p6 and p7 given (ViewSpec._seven).
    schema["required"] = ["p6", "p7"]
    schema["properties"] = {"p6": {"type": "array"}, "p7": {"type": "array"}}


def _station_schema(schema: dict[str, Any]) -> None:
    for option in schema.get("anyOf", []):
        if option.get("type") == "string":
            option["pattern"] = _STATION_ID.pattern


def _auto_schema(schema: dict[str, Any]) -> None:
    options = schema.get("anyOf")
    if isinstance(options, list):
        options.insert(0, {"const": "auto"})


FRAME_KEY = r"^[0-9]+$"
"""A key of `frame_points` in JSON (object keys are strings): a frame index, digits only."""


def _frame_key(value: object) -> object:
    # JSON gives every key as a string: only digits are an index (pydantic alone would also take
    # " 3", "+3" or "1_0", which the published schema refuses).
    if isinstance(value, str) and not re.fullmatch(FRAME_KEY, value, flags=re.ASCII):
        raise ValueError(f"key {value[:32]!r} is not a frame index: give the index in digits only "
                         "(0 the first frame)")
    return value


FrameIndex = Annotated[NonNegativeInt, BeforeValidator(_frame_key)]


def _frame_points_schema(schema: dict[str, Any]) -> None:
    # The keys are frame indices: the schema says so (propertyNames), so that a generated body
    # (or a client) sends only keys the API takes.
    for option in schema.get("anyOf", []):
        if option.get("type") == "object":
            option["propertyNames"] = {"pattern": FRAME_KEY}


_NO_FIRST_VIEW = "(the first view's photo)"


class ViewSpec(_Strict):
    """One photo of the part in a joint fit (`ScanSpec.views`): its reference and its points."""

    image: str = Field(min_length=1, description="The photo: a file path (CLI) or a reference "
                       "(service: upload:ID, s3://bucket/key or an https URL).")
    points: ReferencePoints = Field(description="The seven reference points p1..p7 on this photo, "
                                    "in the documented order; every view marks the same front face "
                                    "(p1 the same corner). All seven are needed: each view is fitted "
                                    "in perspective.", json_schema_extra=_seven_points_schema)
    side_face: SideFace = Field(default="auto", description="The face p4, p5 and p7 mark besides "
                                "the front in this photo (right, left or top; auto reads it from the "
                                "points): each view may show another one.")
    name: str | None = Field(default=None, min_length=1, max_length=200, description="How the view "
                             "is named in the result (e.g. a file name); default: view K, K its "
                             "position in views counted from 1.")

    @field_validator("points", mode="before")
    @classmethod
    def _no_auto(cls, value: object) -> object:
        if value == "auto":
            raise ValueError("points \"auto\" is not supported in a view: a joint fit needs each "
                             "view's seven points (GET /v1/uploads/{id}/points finds them for a "
                             "person to check; send them here)")
        return value

    @field_validator("points")
    @classmethod
    def _seven(cls, points: ReferencePoints) -> ReferencePoints:
        missing = [n for n in ("p6", "p7") if getattr(points, n) is None]
        if missing:
            raise _field_error((missing[0],), f"{missing[0]} is missing: a view needs all seven points "
                               "p1..p7 (each view is fitted in perspective)", None)
        return points


class ScanSpec(_Strict):
    """Everything needed to turn one photo (or a front and a side photo) into a point cloud."""

    # `image` and `points` (or `frame_points`), or `views`: the schema says so too, not only the
    # validators (`image` is filled in from the first view).
    model_config = ConfigDict(json_schema_extra=_spec_schema)

    image: str = Field(min_length=1, description="Front photo (single-photo mode: the only one), "
                       "or a video when `frames` is set.")
    side_image: str | None = Field(
        default=None, description="Side photo; when given, p4, p5 and p7 refer to it.")
    points: ReferencePoints | None = Field(
        default=None, description="Reference points (every frame of a video); required unless "
        "frame_points is given. \"auto\": found in the photo, or in each frame of a video "
        "(prismcore.locate.search), see auto_points.", json_schema_extra=_auto_schema,
    )
    auto_points: AutoPoints | None = Field(
        default=None, description="Set when points is \"auto\": where to look for the box.")
    frames: FrameSelection | None = Field(
        default=None, description="Set when `image` is a video: the frames to measure.")
    frame_points: dict[FrameIndex, ReferencePoints] | None = Field(
        default=None, min_length=1, description="Video with a moving camera: reference points "
        "per frame index (the keys: frame indices, digits only, 0 = the first frame); exactly "
        "these frames are measured.", json_schema_extra=_frame_points_schema,
    )
    points_frame: NonNegativeInt | None = Field(
        default=None, description="Video with a moving camera: the frame index `points` were "
        "marked on; they are carried to every selected frame by tracking "
        "(prismcore.video.tracking), each frame's points written to tracked_points.json, frames "
        "whose track is lost or whose box no longer fits left out with the reason. Needs all "
        "seven points.")
    views: list[ViewSpec] | None = Field(
        default=None, description=f"Several photos of ONE part by one camera (one image size), each "
        f"with its seven points on the same front face, measured as one box in one least-squares fit "
        f"(prismcore.multiview.joint.fit_views): one focal length and lens distortion, a pose per photo, one "
        f"width, height and depth with their 1-sigma. 2 to {JOINT_MAX_VIEWS} views; needs a known "
        f"edge as the scale. A view that disagrees with the others beyond its noise is named and left "
        f"out (3 views or more; two that disagree get a warning). Instead of image and points (image, "
        f"when given, must be the first view's). The item's outputs are the fit's report (joint.json), "
        f"no cloud.", json_schema_extra=_views_schema)
    fit: Literal["frames", "joint"] | None = Field(
        default=None, description="How several views are combined. A video's frames: \"frames\" "
        "(the default) measures each frame as a photo and summarises the medians; \"joint\" "
        f"measures the frames of frame_points (2 to {JOINT_MAX_VIEWS}, seven points each, a known "
        "edge as the scale) as ONE box, as views are, or with points_frame the tracked frames "
        "whose views differ most (up to 30). Items with views are always joint.")
    station: str | None = Field(
        default=None, description="The service: a stored station's id (POST /v1/stations): the part "
        "resting on its support is found and measured in mm from the photo alone (prismcore.station), "
        "with no points and no scale; the photo must come from the station's camera at its image size.",
        json_schema_extra=_station_schema)
    tolerance: float = Field(default=12.0, ge=0.0, le=128.0, description="RGB tolerance per channel.")
    method: Literal["default", "paper"] = "default"
    scale: Scale | None = None
    focal_px: FocalPx | None = Field(
        default=None, description="Focal length in pixels; with p6 and p7 it corrects perspective.")
    principal_point: Point | None = Field(
        default=None, description="Optical centre (x, y) in pixels; the image centre if omitted.")
    camera: CameraModel | None = Field(
        default=None, description="Calibrated camera; trusted after focal_px, before EXIF and "
        "before the focal length fitted from the box."
    )
    side_face: SideFace = Field(
        default="auto", description="One photo: the face p4, p5 and p7 mark besides the front: the "
        "right side (p4 = p2), the left side (p4 = p1, p5 left of it) or the top (p4 = p1, p5 "
        "above it); auto reads it from the points. Two photos: the side photo's face (right).")
    cloud: Literal["surface", "volume"] = "surface"
    formats: list[OutputFormat] = Field(
        default_factory=lambda: list(_DEFAULT_FORMATS), min_length=1, description="The outputs: the "
        "cloud as csv, ply, las or laz (compressed LAS), glb (the fitted box, a textured glTF model), "
        "stl (the box as a mesh), step (the part as a STEP solid, part.step and part.step.json) and "
        "drawing (its dimensioned drawing: drawing.svg, .pdf, .dxf); all but csv and ply "
        "are in mm and need a scale. Not given: the service's default (PRISM_DEFAULT_FORMATS: csv "
        "and ply unless the operator set others; the ones in mm only for an item with a scale); "
        "prism scan and the engine write csv and ply.")
    spacing_mm: PositiveMm | None = Field(
        default=None, description="Thin the cloud so neighbouring points are about this far apart, "
        "mm (one point per voxel of this size); default: one point per pixel (the service's: 1 mm, "
        "PRISM_DEFAULT_SPACING_MM, where in mm; null: per pixel). Needs a scale.")
    nominal: tuple[PositiveMm, PositiveMm, PositiveMm] | None = Field(
        default=None, description="Nominal width, height and depth of the part, mm: the report's "
        "quality block gives each dimension's deviation and a pass/fail/uncertain verdict. Needs "
        "tolerance_mm and a scale.")
    tolerance_mm: NonNegativeMm | tuple[NonNegativeMm, NonNegativeMm, NonNegativeMm] | None = Field(
        default=None, description="Allowed deviation from the nominal, mm: one value for every "
        "dimension, or [width, height, depth]; the limits are nominal ± tolerance, inclusive.")
    csv: CsvOptions = CsvOptions()
    ply_ascii: bool = False
    max_pixels: int = Field(default=50_000_000, gt=0, description="Refuse larger images.")
    max_points: int = Field(default=20_000_000, gt=0, description="Refuse larger clouds.")
    reference: str | None = Field(
        default=None, max_length=200, description="Your own id for the item (a part number, a file's "
        "name): echoed in its results (results.csv's item_reference); the scan does not read it.")

    @model_validator(mode="before")
    @classmethod
    def _auto_points(cls, data: object) -> object:
        # "points": "auto" is kept as points None plus auto_points, so that code past the
        # search (which fills points) sees reference points or nothing.
        if isinstance(data, dict) and data.get("points") == "auto":
            if data.get("views") is not None:
                # Said here: past this point "auto" is auto_points, which the user did not send.
                raise _field_error(("points",), "points \"auto\" does not go with views: each view "
                                   "carries its own seven points (a joint fit does not search for "
                                   "them; GET /v1/uploads/{id}/points finds them for a person to "
                                   "check, then send them in the view); drop points", "auto")
            return {**data, "points": None, "auto_points": data.get("auto_points") or {}}
        return data

    @model_validator(mode="before")
    @classmethod
    def _image_from_views(cls, data: object) -> object:
        # The first view's photo is the item's `image`, so code that names an item's input (and
        # the stored record) has one field to read.
        if isinstance(data, dict) and data.get("image") is None and data.get("views") is not None:
            views = data["views"]
            first = views[0] if isinstance(views, list) and views else None
            image = first.get("image") if isinstance(first, dict) else getattr(first, "image", None)
            # Views without a first photo (none, not a list, the first one bad) are wrong in
            # views, not in image: `_NO_FIRST_VIEW` stands in for image so that only views' own
            # error is told (the field's, or `_joint_consistent`'s count). Such views never
            # validate, so it never reaches a spec.
            return {**data, "image": image if isinstance(image, str) and image else _NO_FIRST_VIEW}
        return data

    @model_validator(mode="before")
    @classmethod
    def _frames_from_frame_points(cls, data: object) -> object:
        # Per-frame points decide which frames are measured; `frames` then says so explicitly,
        # so code that asks "is this a video?" needs to look at one field only.
        if isinstance(data, dict) and data.get("frame_points") and data.get("frames") is None:
            keys = data["frame_points"]
            if isinstance(keys, dict):
                try:
                    indices = sorted({int(k) for k in keys})
                except (TypeError, ValueError):
                    return data  # the field's own validation names the bad key
                if indices[0] < 0:
                    return data
                return {**data, "frames": {"indices": indices}}
        return data

    @field_validator("station")
    @classmethod
    def _station_id(cls, value: str | None) -> str | None:
        if value is not None and not _STATION_ID.match(value):
            raise ValueError(f"station {value[:64]!r} is not a station id (32 lowercase hex digits, "
                             "as POST /v1/stations answers)")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> ScanSpec:
        if self.station is not None:
            self._station_consistent()
        if self.views is not None or self.fit is not None:
            self._joint_consistent()
        if isinstance(self.scale, Pinhole) and self.focal_px is None and self.camera is None \
                and not self._focal_fittable():
            raise ValueError("a shooting distance needs focal_px (the focal length in pixels), "
                             "a camera, or p6 and p7 in one photo (the focal length is fitted)")
        if self.points_frame is not None:
            self._points_frame_consistent()
        if self.frame_points is not None:
            if self.auto_points is not None:
                raise ValueError("points \"auto\" finds the points in every frame: drop frame_points")
            if self.points is not None:
                raise ValueError("give points (the same for every frame) or frame_points "
                                 "(per frame), not both")
            listed = sorted(self.frame_points)
            if self.frames is None or self.frames.indices is None or sorted(self.frames.indices) != listed:
                raise ValueError(f"frame_points measures exactly frames {listed}: drop frames or "
                                 f"give frames.indices equal to them, got frames={self._frames_text()}")
        elif self.auto_points is not None:
            if self.points is not None:
                raise ValueError("auto_points goes with points \"auto\": drop one of them")
            if self.side_image is not None:
                raise ValueError("points \"auto\" is for one photo (or a video's frames): not with "
                                 "side_image")
            if self.side_face != "auto":
                raise ValueError(f"side_face {self.side_face!r} goes with clicked points: with points "
                                 "\"auto\" the search tells the face itself; drop side_face")
        elif self.points is None and self.views is None and self.station is None:
            raise ValueError("points: the reference points are missing (give points, \"auto\" "
                             "to have them found in the photo, or frame_points for a video)")
        if self.side_image is not None and self.side_face in ("left", "top"):
            raise ValueError(f"side_face {self.side_face!r} is for one photo: with side_image "
                             f"{self.side_image!r}, p4, p5 and p7 mark the side face as photographed "
                             "(a right side); drop side_face or give 'right'")
        if (self.nominal is None) != (self.tolerance_mm is None):
            given, missing = (("nominal", "tolerance_mm") if self.nominal is not None
                              else ("tolerance_mm", "nominal"))
            raise ValueError(f"{given} needs {missing}: give both (the nominal size and the "
                             "allowed deviation from it)")
        metric = [f"{n}" for n in ("nominal", "spacing_mm") if getattr(self, n) is not None]
        metric += [f"format {f!r}" for f in self.formats if f in METRIC_FORMATS]
        if metric and self.scale is None and self.station is None:
            raise ValueError(f"{metric[0]} is in mm or metres, but without a scale the dimensions "
                             "are in pixels: give a scale (mm_per_px, a pinhole distance or a known edge)")
        if self.frames is not None and self.side_image is not None:
            raise ValueError(f"a video is measured in single-photo mode: side_image "
                             f"{self.side_image!r} cannot be used with frames")
        return self

    def _points_frame_consistent(self) -> None:
        """`points_frame`: seven clicked points on one frame of a video, tracked to the others."""
        if self.frames is None:
            raise _field_error(("points_frame",), "points_frame is for a video (with frames): a photo's "
                               "points are its own", self.points_frame)
        if self.points is None:
            raise _field_error(("points_frame",), "points_frame names the frame points were marked on: "
                               "give points (seven clicked points; not \"auto\", not frame_points)",
                               self.points_frame)
        missing = [p for p in ("p6", "p7") if getattr(self.points, p) is None]
        if missing:
            raise _field_error(("points", missing[0]), f"{missing[0]} is missing: tracking from "
                               "points_frame needs all seven points p1..p7", None)

    def _station_consistent(self) -> None:
        """A station item: the photo alone, measured on the station (no points, no scale)."""
        for name in _STATION_ASIDE:
            given = self.auto_points is not None if name == "points" and self.points is None \
                else self._changed(name)
            if given:
                raise _field_error((name,), f"{name} does not go with a station: {_STATION_ASIDE[name]}",
                                   getattr(self, name))

    def _joint_consistent(self) -> None:
        """The rules of `views` and `fit`, each error at the field at fault."""
        def fail(loc: tuple[str | int, ...], message: str, value: object) -> None:
            raise _field_error(loc, message, value)

        if self.views is not None:
            n = len(self.views)
            if n < 2:
                fail(("views",), f"views: a joint fit needs at least 2 views of the part, got {n} (one "
                     "photo is an item with image and points)", n)
            if n > JOINT_MAX_VIEWS:
                fail(("views",), f"views: at most {JOINT_MAX_VIEWS} views are measured together, got {n}", n)
            seen: dict[str, int] = {}
            for k, v in enumerate(self.views):
                if (first := seen.setdefault(v.image, k)) != k:
                    fail(("views", k, "image"), f"views.{k}.image {v.image!r} is views.{first}'s photo "
                         "again: a photo counted twice would claim twice the evidence it holds", v.image)
            if self.image != self.views[0].image:
                fail(("image",), f"image {self.image!r} is not the first view's {self.views[0].image!r}: "
                     "with views, drop image (the first view's photo is the item's image)", self.image)
            if self.fit == "frames":
                fail(("fit",), "fit \"frames\" is for a video's frames: views are measured as one box "
                     "(drop fit, or give \"joint\")", self.fit)
            # Each view carries its own points; one camera without a lens model; no cloud.
            for name in ("points", "auto_points", "frame_points", "frames", "side_image", "camera",
                         "principal_point", "spacing_mm", "side_face", "method", "cloud", *_CLOUD_ONLY):
                if self._changed(name):
                    fail((name,), f"{name} does not go with views: " + _JOINT_ASIDE.get(
                        name, "each view carries its own points and side_face"), getattr(self, name))
            if self._cloud_formats_asked():
                fail(("formats",), "formats does not go with views: " + _JOINT_ASIDE["formats"], self.formats)
        elif self.fit == "joint" and self.points_frame is not None:
            for name in ("camera", "principal_point", "spacing_mm"):
                if getattr(self, name) is not None:
                    fail((name,), f"{name} does not go with fit \"joint\": " + _JOINT_ASIDE[name],
                         getattr(self, name))
        elif self.fit == "joint":
            if self.frame_points is None:
                where = "points" if self.points is not None or self.auto_points is not None else "fit"
                fail((where,), "fit \"joint\" measures a video's frames with points per frame as one "
                     "box: give frame_points (2 or more frames, seven clicked points each; several photos "
                     "go in views)", self.fit)
            assert self.frame_points is not None
            n = len(self.frame_points)
            if n < 2:
                fail(("frame_points",), f"frame_points: fit \"joint\" needs at least 2 frames, got {n}", n)
            if n > JOINT_MAX_VIEWS:
                fail(("frame_points",), f"frame_points: fit \"joint\" measures at most {JOINT_MAX_VIEWS} "
                     f"frames together, got {n}", n)
            for index, points in sorted(self.frame_points.items()):
                missing = [p for p in ("p6", "p7") if getattr(points, p) is None]
                if missing:
                    fail(("frame_points", index, missing[0]), f"frame_points {index}: {missing[0]} is "
                         "missing: fit \"joint\" needs all seven points p1..p7 of every frame", None)
            for name in ("camera", "principal_point", "spacing_mm"):
                if getattr(self, name) is not None:
                    fail((name,), f"{name} does not go with fit \"joint\": " + _JOINT_ASIDE[name],
                         getattr(self, name))
            changed = [name for name, off in (("method", self._changed("method")),
                                              ("cloud", self._changed("cloud")),
                                              ("formats", self._cloud_formats_asked()),
                                              *((n, self._changed(n)) for n in _CLOUD_ONLY))
                       if off]
            if changed:
                name = changed[0]
                fail((name,), f"{name} does not go with fit \"joint\": " + _JOINT_ASIDE[name],
                     getattr(self, name))
        elif self.fit == "frames" and self.frames is None:
            fail(("fit",), "fit is for a video's frames (\"frames\" or \"joint\"); a photo is measured "
                 "alone, several photos go in views", self.fit)
        if (self.fit == "joint" or self.views is not None) and not isinstance(self.scale, KnownEdge):
            fail(("scale",), "a joint fit needs one known edge of the part as its scale "
                 "({\"kind\": \"edge\", \"edge\": \"width\", \"length_mm\": ...}): it sets the "
                 "millimetres of every view", None if self.scale is None else self.scale.kind)

    def _changed(self, name: str) -> bool:
        """Is field `name` other than its default? (The value, not whether it was given: a stored
        record reads back with every default written out.)"""
        default = type(self).model_fields[name].get_default(call_default_factory=True)
        return bool(getattr(self, name) != default)

    def _formats_asked(self) -> bool:
        """Does the spec ask for cloud formats other than the default? (In any order: a stored
        record reads back with the default written out, so the value, not whether it was given,
        is what can be judged.)"""
        return bool(self.formats) and set(self.formats) != set(_DEFAULT_FORMATS)

    def _cloud_formats_asked(self) -> bool:
        """Does the spec ask for formats other than the default and the part's (step, drawing, stl),
        which a joint fit (no cloud) writes from its report?"""
        return self._formats_asked() and not set(self.formats) <= set(PART_FORMATS)

    @property
    def part_formats(self) -> list[OutputFormat]:
        """The formats asked for that a joint fit writes: step, drawing and stl."""
        return [f for f in self.formats if f in PART_FORMATS] if self._formats_asked() else []

    def _focal_fittable(self) -> bool:
        """One photo with all seven points: the box fit finds the focal length itself."""
        if self.two_photo:
            return False
        if self.auto_points is not None:
            return True  # the search finds all seven points
        marks = [self.points] if self.points is not None else list((self.frame_points or {}).values())
        return bool(marks) and all(p.p6 is not None and p.p7 is not None for p in marks)

    def _frames_text(self) -> str:
        return "null" if self.frames is None else self.frames.model_dump_json(exclude_none=True)

    @property
    def two_photo(self) -> bool:
        return self.side_image is not None

    @property
    def is_video(self) -> bool:
        """True when `image` names a video (the spec has a frame selection)."""
        return self.frames is not None

    @property
    def kind(self) -> ItemKind:
        """What the item is, read from its fields: `prismcore.spec_fields.item_kind`."""
        return item_kind(self)


_STATION_ID = re.compile(r"^[0-9a-f]{32}$")
_STATION_FOUND = "the station finds the part and fits the box itself"
_STATION_ASIDE = {
    "points": _STATION_FOUND + " (its seven points are derived from the fit); drop points",
    "frame_points": _STATION_FOUND + " in one photo; drop frame_points",
    "frames": "a station measures photos, not videos; drop frames",
    "views": "a station measures each photo alone; give one item per photo",
    "fit": "a station measures each photo alone; drop fit",
    "side_image": "a station measures one photo; drop side_image",
    "side_face": _STATION_FOUND + "; drop side_face",
    "method": _STATION_FOUND + "; drop method",
    "scale": "the station's calibrated support plane gives the millimetres; drop scale",
    "focal_px": "the station's calibrated camera is used; drop focal_px",
    "principal_point": "the station's calibrated camera is used; drop principal_point",
    "camera": "the station's calibrated camera is used; drop camera",
}

_CLOUD_ONLY = ("tolerance", "csv", "ply_ascii", "max_points")
"""Options of the cloud a photo's scan makes, which a joint fit (no cloud) would silently ignore."""

_NO_CLOUD = "a joint fit writes its report (joint.json), no cloud"

_JOINT_ASIDE = {
    "auto_points": "it says where points \"auto\" looks, and each view carries its own seven points",
    "frames": "views are photos (a video's frames measured as one box are frame_points with fit "
              "\"joint\")",
    "side_image": "each view is one photo with its own second face (side_face); a side photo is "
                  "another view",
    "tolerance": "the RGB tolerance is the colour scan's, which makes a photo's cloud; " + _NO_CLOUD,
    "csv": _NO_CLOUD,
    "ply_ascii": _NO_CLOUD,
    "max_points": _NO_CLOUD,
    "camera": "the joint fit finds one focal length and lens distortion from the views themselves "
              "(give focal_px if it is known)",
    "principal_point": "the joint fit takes the image centre as the optical centre",
    "spacing_mm": _NO_CLOUD,
    "formats": _NO_CLOUD + "; formats may ask for the part's step, drawing and stl only",
    "cloud": _NO_CLOUD,
    "method": "the joint fit is the default method's perspective fit",
}


def view_spec(spec: ScanSpec, k: int) -> ScanSpec:
    """The photo spec of view `k` of a spec with views: its photo, points and side face, with the
    item's scale and focal length (what the engine's single-photo checks take)."""
    if spec.views is None:
        raise ValueError("view_spec needs a spec with views")
    view = spec.views[k]
    return ScanSpec.model_validate({
        "image": view.image, "points": view.points.model_dump(), "side_face": view.side_face,
        "scale": None if spec.scale is None else spec.scale.model_dump(), "focal_px": spec.focal_px,
        "max_pixels": spec.max_pixels})



"""What the API accepts and answers: the public shapes, separate from the stored records.

The job's own shape (`JobPublic` and its parts) lives in `prism_common.public`, because the
worker's webhook sends the very same document."""

from __future__ import annotations

import math
from typing import Any, Literal

from prism_common.public import DimensionsPublic, ItemPublic, JobList, JobPublic, ResultPublic
from pydantic import BaseModel, ConfigDict, Field, field_validator

from prismcore.spec import ScanSpec

__all__ = ["DimensionsPublic", "FoundPointsPublic", "ItemPublic", "JobCreate", "JobList", "JobPublic",
           "ResultPublic", "UploadProbe", "UploadPublic", "VideoPublic"]


def _first_non_finite(value: Any, path: str = "") -> str | None:
    """The path of the first NaN/Infinity in parsed JSON, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return path or "value"
    if isinstance(value, dict):
        found = (_first_non_finite(v, f"{path}.{k}" if path else str(k)) for k, v in value.items())
    elif isinstance(value, list | tuple):
        found = (_first_non_finite(v, f"{path}[{i}]") for i, v in enumerate(value))
    else:
        return None
    return next((f for f in found if f is not None), None)


def _webhook_schema(schema: dict[str, Any]) -> None:
    # An http(s) URL with a host (prism_common.outbound); which hosts is the operator's list.
    for option in schema.get("anyOf", []):
        if option.get("type") == "string":
            option.update(format="uri", pattern="^[Hh][Tt][Tt][Pp][Ss]?://[^/?#@]+")


class JobCreate(BaseModel):
    """A batch of scans: each item is the `prism scan --spec` model, images given as references."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{
        # samples/box.jpg's seven points, in the form the schema names (a list of pairs is
        # taken too, but the schema does not say so)
        "items": [{"image": "upload:0123456789abcdef0123456789abcdef",
                   "points": {"p1": [395, 293], "p2": [943, 331], "p3": [919, 761], "p4": [943, 331],
                              "p5": [1035, 298], "p6": [411, 647], "p7": [1009, 660]},
                   "scale": {"kind": "edge", "edge": "width", "length_mm": 120}}],
        "client_reference": "batch-17"}]})

    items: list[ScanSpec] = Field(min_length=1, description="The scans, run in order.")
    client_reference: str | None = Field(default=None, max_length=200,
                                         description="Your own id for the batch, echoed back.")
    webhook_url: str | None = Field(default=None, max_length=2000,
                                    json_schema_extra=_webhook_schema,
                                    description="POSTed the finished job, signed by the Standard "
                                                "Webhooks spec. https (http only where the "
                                                "service allows it), on an allow-listed host.")

    @field_validator("items")
    @classmethod
    def _finite_numbers(cls, items: list[ScanSpec]) -> list[ScanSpec]:
        # Python's JSON parser accepts NaN/Infinity (and 1e400 as Infinity), and a few spec fields
        # (principal_point) do not check finiteness; stored, they would come back as null and
        # break the record for good. After the items' own validation, so that a field that does
        # check (a point) is pointed at itself, not at /items.
        for i, item in enumerate(items):
            if (where := _first_non_finite(item.model_dump())) is not None:
                raise ValueError(f"item {i}: {where} is not a finite number")
        return items


class UploadProbe(BaseModel):
    """What the file was found to be when it was stored (the engine's own header readers)."""

    kind: Literal["image", "video"]
    format: str = Field(description='"BMP", "PNG", "JPEG", "TIFF", "WEBP"; for videos "AVI", '
                        '"MP4", "MOV" or "MKV".')
    width: int | None = Field(default=None, description="Pixels, as the engine sees the photo "
                              "(after EXIF orientation) or the video's frames; null if unread.")
    height: int | None = None
    frame_count: int | None = Field(default=None, description="Videos: frames that decode.")
    fps: float | None = None
    codec: str | None = None
    error: str | None = Field(default=None, description="Why the size could not be read: the "
                              "file is damaged (a job naming it fails with this reason).")


class UploadPublic(BaseModel):
    id: str
    reference: str = Field(description="Use as an item's image: `upload:ID`.")
    size: int
    name: str
    probe: UploadProbe | None = None
    sha256: str | None = Field(default=None, description="SHA-256 of the content (hex). The "
                               "same file (content and name) sent again is answered (200, not "
                               "201) with the upload already stored.")


class VideoPublic(BaseModel):
    """An uploaded video as the worker decodes it (`prismcore.video.frames.probe_video`)."""

    id: str = Field(description="The upload's id.")
    frame_count: int = Field(description="Frames that decode; frame i is shown at i / fps s.")
    fps: float = Field(description="Frames per second the file states (0: none stated).")
    width: int = Field(description="Frame width, px.")
    height: int = Field(description="Frame height, px.")
    codec: str = Field(description='FourCC as OpenCV reports it, e.g. "MJPG", "FMP4", "h264".')
    duration_s: float


class FoundPointsPublic(BaseModel):
    """The box and its reference points the zero-click search (`prismcore.locate.search`) found in an
    upload, for a person to check: either `points` or a `reason`."""

    id: str = Field(description="The upload's id.")
    frame: int | None = Field(description="The video frame searched; null for a photo.")
    hint: tuple[int, int] | None = Field(description="The hint searched around, (x, y) whole px.")
    width: int = Field(description="The photo's (frame's) width as the engine decodes it, px.")
    height: int = Field(description="Its height, px.")
    points: dict[str, list[float]] | None = Field(
        description="p1..p7, image (x, y) px, in the documented order (p4, p5, p7 on the "
                    "`side_face`); null when the search refused (see `reason`).")
    side_face: Literal["right", "left", "top"] | None = Field(
        description="The second face p4, p5 and p7 mark; null when refused.")
    confidence: float = Field(description="0-1: how well a box explains the edges found.")
    reason: str | None = Field(
        description="Why no points are given, in words a person can act on (no box found, two "
                    "candidate boxes: give a hint, only one face visible, uncertain); null when found.")
    warnings: list[str] = Field(description="Found with a modest confidence: check the points.")
    faces: list[list[list[float]]] = Field(
        description="The faces found, each four (x, y) px corners (for an overlay); empty when refused.")

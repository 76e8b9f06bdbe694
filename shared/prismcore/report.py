"""report.json as a typed model: one photo's (or one video frame's, or one station photo's)
measurement, the contract between the engine's stages, the services, the page and integrators.

Pydantic only, like `prismcore.spec` (no numpy, no OpenCV). Every mode builds a `ScanReport`
(`prismcore.scan.build_report`, the station's `prismcore.station.scan`, the search's
`prismcore.locate.record_found`, a video frame's `frame`) and every reader reads its attributes;
`report_dict` is report.json's content.

Which keys a report.json has depends on its mode (`auto_points` only with found points,
`station` only on a station or a board, `frame` only for a video's frame, ...): the file holds
exactly the fields its mode set (`model_dump(exclude_unset=True)`), so a field that is null in
the file (`uncertainty` when the fit gave no covariance) was set to null, and one the mode does not
give is absent. The blocks are closed (`extra="forbid"`) but for `inputs`, the spec as run
(`ScanSpec`'s JSON, as the job spec's schema describes it), and the station's
`registration.board_corners`, which are the board detector's own record.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, WithJsonSchema

__all__ = [
    "Camera",
    "DimensionVerdict",
    "Dimensions",
    "Drift",
    "EdgeUse",
    "Face",
    "FaceEdge",
    "Fit",
    "FoundPoints",
    "FrameInfo",
    "ImageSize",
    "Quality",
    "Registration",
    "ScanReport",
    "Sigma",
    "StationBlock",
    "VerificationState",
    "report_dict",
    "report_schema",
]

# A figure as the engine rounded it: an int stays an int in the file (its schema: a JSON number).
Number = Annotated[int | float, WithJsonSchema({"type": "number"})]
Side = Literal["right", "left", "top"]


class _Block(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Dimensions(_Block):
    """The box's size: width (X, P1 to P2), height (Y, down the front), depth (Z, into the object)."""

    width: Number = Field(description="X, P1 to P2, in `unit`")
    height: Number = Field(description="Y, down the front face, in `unit`")
    depth: Number = Field(description="Z, into the object, in `unit`")
    unit: Literal["mm", "px"] = Field(description="mm with a scale, px without")


class Sigma(_Block):
    """One standard deviation of each dimension, in the dimensions' unit."""

    width: Number | None = Field(description="the width's standard deviation (0 for a known edge)")
    height: Number | None = Field(description="the height's standard deviation")
    depth: Number | None = Field(description="the depth's standard deviation")


class Camera(_Block):
    """The camera the fit used."""

    focal_px: Number | None = Field(
        description="the focal length, px of the decoded photo; null when none was known or fitted")
    focal_source: Literal["given", "camera", "exif", "pooled", "fitted", "none"] = Field(
        description="where the focal length came from, in its order of trust")
    principal_point: list[Number] = Field(description="(x, y) px of the front photo")
    focal_std_px: Number | None = Field(
        None, description="the focal length's standard error, px (fitted or pooled)")
    pooled_photos: int | None = Field(None, description="how many photos the pooled focal length came from")
    undistorted: bool | None = Field(
        None, description="true when the photo's lens distortion was removed first")


class EdgeUse(_Block):
    """What one side of a face rests on."""

    side: Literal["top", "right", "bottom", "left"] = Field(description="the face's side")
    used: Literal["edge", "click"] = Field(
        description="edge: the photo's refined edge; click: the clicked side")
    why: str = Field(description="why, in words")


class Fit(_Block):
    """How far the fitted box lies from the points."""

    rms_px: Number | None = Field(None, description="RMS distance of the clicks to the fitted corners, px")
    point_residuals_px: dict[str, Number] | None = Field(
        None, description="each point's (p1 ... p7) distance to its fitted corner, px; over 3 px warns")
    edges: dict[str, list[EdgeUse]] | None = Field(
        None, description="per face (front, side), per side, the edge or the click it rests on")


class FaceEdge(_Block):
    """One side's sub-pixel edge fit."""

    side: Literal["top", "right", "bottom", "left"] = Field(description="the face's side")
    fitted: bool = Field(description="true when an edge was found along it")
    support: Number = Field(description="the share of the side the edge was seen along, 0-1")
    rms_px: Number = Field(description="the edge points' RMS distance to the fitted line, px")


class Face(_Block):
    """One scanned face."""

    corners: list[list[Number]] = Field(description="the fitted quadrilateral's four corners, (x, y) px")
    object_pixels: int = Field(description="pixels of the part the scan kept")
    marked_pixels: int = Field(description="pixels the points marked")
    point_loss: Number = Field(description="the share of the marked pixels that fell outside the part, 0-1")
    edges: list[FaceEdge] | None = Field(None, description="each side's edge fit (method default)")


class ImageSize(_Block):
    """A photo's size as decoded."""

    width: int = Field(description="px")
    height: int = Field(description="px")


class DimensionVerdict(_Block):
    """One dimension against its nominal size."""

    nominal_mm: Number = Field(description="the nominal size, mm")
    measured_mm: Number = Field(description="the measured size, mm")
    deviation_mm: Number = Field(description="measured minus nominal, mm")
    tolerance_mm: Number = Field(description="T of the tolerance +-T, mm")
    sigma_mm: Number | None = Field(description="the measurement's standard deviation, mm; null unknown")
    interval_mm: list[Number] = Field(description="the deviation's interval, +-k sigma, mm")
    verdict: Literal["pass", "fail", "uncertain"] = Field(
        description="pass: the interval lies within the tolerance; fail: wholly outside; else uncertain")


class Quality(_Block):
    """The part against its nominal size and tolerance (`prismcore.quality`)."""

    verdict: Literal["pass", "fail", "uncertain"] = Field(
        description="fail if any fails, else uncertain if any is")
    k: Number = Field(description="the interval's coverage factor (sigma multiples)")
    counts: dict[str, int] = Field(description="how many dimensions pass, fail, are uncertain")
    dimensions: dict[str, DimensionVerdict] = Field(description="per dimension (width, height, depth)")


class FoundPoints(_Block):
    """The zero-click search's result (`prismcore.locate.Found.report`)."""

    points_source: Literal["auto"] = Field(description="always auto")
    confidence: Number = Field(description="the search's confidence, 0-1")
    side_face: Side | None = Field(description="the second face found")
    reason: str | None = Field(description="why nothing was found; null when found")
    points: dict[str, list[Number]] | None = Field(description="p1 ... p7 found, (x, y) px")
    candidates: int = Field(description="how many boxes the search weighed")
    warnings: list[str] = Field(description="the search's warnings (a low confidence: check the points)")
    stable: bool = Field(description="false when a face rests on one sampling only, or on a fallback")
    fit_rms_px: Number | None = Field(description="the PnP screen's reprojection RMS, px")


class FrameInfo(_Block):
    """A video frame's place in its video."""

    index: int = Field(description="the frame's index, from 0")
    time_s: Number | None = Field(description="its time, s; null without a frame rate")


class Registration(_Block):
    """How the photo was put back on the station's plate (or the board found)."""

    source: Literal["board", "plate", "unmoved", "none"] = Field(
        description="what registered it: board (its corners found again), plate (the support's own "
        "features), unmoved (the camera found where it was calibrated: the calibration's pose and "
        "plate used as they are), none (no plate to register on)")
    shift_px: Number = Field(description="how far the support moved in the photo since calibration, px")
    board_corners: Any = Field(description="the board's corners used (the detector's record)")


class VerificationState(_Block):
    """The station's verification as this measurement states it (`prismcore.station.certify`)."""

    status: Literal["verified", "not verified", "verified before the camera moved"]
    date: str | None = Field(description="the verification's date (ISO 8601); null when never verified")
    bias_mm: dict[str, Number] | None = Field(description="per dimension, the verification's bias, mm")
    repeatability_mm: dict[str, Number] | None = Field(description="per dimension, its repeatability, mm")
    tolerance_mm: Number | None = Field(description="the tolerance it was verified for, mm")
    text: str = Field(description="the status in words")
    warning: str | None = Field(description="the warning it adds, or null")


class Drift(_Block):
    """How far the camera moved since calibration, and what it may cost
    (`prismcore.station.certify.drift`)."""

    shift_px: Number = Field(description="the re-registration's shift, px in the photo")
    shift_mm: Number = Field(description="the same on the support, mm")
    moved: bool = Field(description="true past `moved_over_px`")
    moved_over_px: Number = Field(description="the shift the camera counts as moved past, px")
    cost_mm: dict[str, Number] = Field(
        description="per dimension, what the shift may cost if not followed, mm")
    allowed_mm: dict[str, Number] = Field(description="per dimension, a third of its tolerance, mm")
    tolerance_from: str = Field(description="where the tolerance came from, in words")
    threshold_px: Number | None = Field(description="the shift that would cost a third of the tolerance, px")
    reverify: bool = Field(description="true when the station should be verified again")


class StationBlock(_Block):
    """A measurement on a station (or a hand-held board): the station's own fit."""

    scale_source: Literal["station", "board"] = Field(description="always station (the fit's own record)")
    dimensions: Dimensions = Field(description="the station's fit, mm")
    uncertainty: Sigma = Field(description="its standard deviations, mm")
    position_mm: list[Number] = Field(description="the part's (x, y) on the support, mm")
    yaw_deg: Number = Field(description="the part's turn on the support, degrees")
    silhouette_residual_px: Number = Field(description="the outline's RMS distance to the fitted box, px")
    contrast: Number = Field(description="the part's contrast against the support")
    registration: Registration
    points: list[list[Number]] = Field(description="the seven points derived from the fit, (x, y) px")
    side_face: Side = Field(description="the second face the derived points mark")
    warnings: list[str] = Field(description="the measurement's warnings")
    timings_ms: dict[str, Number] = Field(description="each stage's time, ms")
    verification: VerificationState | None = Field(None, description="on a station: its verification")
    drift: Drift | None = Field(None, description="on a station: the camera's drift since calibration")


class ScanReport(BaseModel):
    """report.json: one photo's (or video frame's, or station photo's) measurement.

    The file holds the fields its mode set (see the module's notes): a photo's scan sets all but
    `scale_source`, `points_source`, `auto_points`, `station`, `engine_dimensions` and `frame`;
    found points add `points_source` and `auto_points`; a video frame `frame`; a station photo
    (or a board's) `scale_source`, `points_source`, `station` and `engine_dimensions`, and when its
    derived points made no cloud only `warnings`, `timings_ms` and those.
    """

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    points: int | None = Field(None, description="the number of points in the cloud")
    dimensions: Dimensions = Field(description="the measured size (a station's: its own fit)")
    uncertainty: Sigma | None = Field(
        None, description="each dimension's standard deviation; null without one")
    camera: Camera | None = Field(None, description="the camera the fit used")
    fit: Fit | None = Field(None, description="the fitted box against the points")
    point_loss: Number | None = Field(
        None, description="the share of the marked region outside the part, 0-1")
    method: Literal["default", "paper"] | None = Field(
        None, description="default: sub-pixel edges; paper: the paper's colour scan")
    side_face: Side | None = Field(None, description="which second face P4, P5 (P7) marked")
    cloud: Literal["surface", "volume"] | None = Field(None, description="the cloud's kind")
    perspective_corrected: bool | None = Field(
        None, description="true when the pose was fitted through a pinhole camera")
    faces: dict[str, Face] | None = Field(None, description="per face (front, side): its scan")
    warnings: list[str] = Field(description="every warning, in words")
    timings_ms: dict[str, Number] = Field(description="each stage's time, ms (the writers' too)")
    images: list[ImageSize] | None = Field(None, description="each photo's size as decoded")
    inputs: dict[str, Any] | None = Field(
        None, description="the spec as run, points included (the job spec's JSON)")
    engine_version: str | None = Field(None, description="the engine's version")
    quality: Quality | None = Field(None, description="the verdicts against a nominal size; null without one")
    points_source: Literal["auto", "station", "board"] | None = Field(
        None, description="auto: found by the search; station or board: derived from the station's fit; "
                          "absent when clicked")
    auto_points: FoundPoints | None = Field(None, description="the search's result (points auto)")
    scale_source: Literal["station", "board"] | None = Field(
        None, description="on a station or a board: where the mm came from")
    engine_dimensions: Dimensions | None = Field(
        None, description="on a station: the photo pipeline's reading of the derived points (the "
                          "cloud's size)")
    station: StationBlock | None = Field(
        None, description="on a station or a board: the station's measurement")
    frame: FrameInfo | None = Field(None, description="a video frame's index and time")


def report_dict(report: ScanReport) -> dict[str, Any]:
    """report.json's content: the fields the report's mode set, as JSON-ready Python values."""
    return report.model_dump(exclude_unset=True)


def report_schema() -> dict[str, Any]:
    """report.json's JSON Schema (published as docs/reference/report.schema.json; `prism schema
    --report` prints it). A field a mode does not set is absent from the file, not null: the
    schema gives no defaults."""
    schema = ScanReport.model_json_schema(mode="serialization")
    for model in [schema, *schema["$defs"].values()]:
        for field in model.get("properties", {}).values():
            field.pop("default", None)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}

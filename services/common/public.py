"""The job as clients see it: one shape for `GET /v1/jobs/{id}` and for the webhook's body.

Separate from the stored records (`records.py`): the tenant stays private, and output object
keys become presigned download URLs, made by whoever answers (the API, or the worker for a
webhook) through the `url_for(key, filename)` it passes in.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, Field

from prismcore.spec import FILE_NAMES, frame_folder

from .records import ItemResult, ItemState, JobRecord, State

__all__ = ["VERDICTS", "DimensionsPublic", "FramePublic", "ItemPublic", "JobList", "JobPublic",
           "JointLeftOutPublic", "JointPublic", "JointViewPublic", "ResultPublic", "ResultsTable",
           "StationCheckPublic", "StationDriftPublic", "StationVerificationPublic",
           "download_name", "to_public"]


VERDICTS = ("pass", "fail", "uncertain")
"""A part's verdicts against its nominal size (prismcore.quality.verdicts.Verdict)."""


class DimensionsPublic(BaseModel):
    width: float
    height: float
    depth: float
    unit: str


class JointDimensions(BaseModel):
    width: float
    height: float
    depth: float


class JointViewPublic(BaseModel):
    """One view the joint fit used."""

    index: int = Field(description="The view's position in the item's `views` (0 = the first); for "
                       "a video, the frame's index.")
    name: str = Field(description="The view's `name`, or \"view K\" (K = index + 1); \"frame N\" "
                      "for a video.")
    click_rms_px: float = Field(description="RMS distance, px, of the shared box's corners from this "
                                "view's points.")
    line_rms_px: float = Field(description="RMS distance, px, of the box's edges from this view's "
                               "refined edge lines (0 when none was refined).")
    alone: JointDimensions = Field(description="What this view measures by itself, in the "
                                   "dimensions' unit.")
    disagreement: float | None = Field(description="Its chi-square against the other views (3 "
                                       "views or more; null with 2).")
    lines_left_out: int = Field(0, description="Its refined edge lines left out: farther from the "
                                "box the views share than a line's noise allows (a printed border, "
                                "a shadow taken for an edge); its points still count.")


class JointLeftOutPublic(BaseModel):
    """A view the joint fit left out."""

    index: int = Field(description="As JointViewPublic.index.")
    name: str
    reason: str = Field(description="Why, in words with its figures: measured alone it is refused "
                        "(its points), or it disagrees with the other views beyond its noise (what "
                        "it measures alone against what the others measure).")


class JointPublic(BaseModel):
    """Several views of one part measured as ONE box (prismcore.multiview.joint.fit_views)."""

    views: list[JointViewPublic] = Field(description="The views used, in input order.")
    left_out: list[JointLeftOutPublic] = Field(description="The views not used, with the reason.")
    focal_std_px: float | None = Field(description="1 sigma of the fitted focal length; null when "
                                       "it was given.")
    distortion_kappa: float = Field(description="The radial lens distortion read from every view's "
                                    "edges together (the division model's kappa).")


class StationVerificationPublic(BaseModel):
    status: Literal["verified", "not verified", "verified before the camera moved"] = Field(
        description="The station's verification with a reference part as this measurement stands: "
        "verified (on `date`), not verified (none, or the last one failed), or verified before the "
        "camera moved (more than `drift.moved_over_px` since calibration).")
    text: str = Field(description="The status in words, with each dimension's bias and repeatability.")
    date: datetime | None = Field(description="When the station was last verified; null if never.")
    bias_mm: dict[str, float] | None = Field(description="The verification's bias per dimension.")
    repeatability_mm: dict[str, float] | None = Field(
        description="The verification's repeatability per dimension.")
    tolerance_mm: float | None = Field(description="The verification's T of +-T.")
    warning: str | None = Field(description="The warning this status adds to the result's (null when "
                                "verified).")


class StationDriftPublic(BaseModel):
    shift_px: float = Field(description="How far the support moved in the photo since calibration "
                            "(the re-registration's median shift), px.")
    shift_mm: float = Field(description="The same on the support, mm.")
    moved: bool = Field(description="shift_px over moved_over_px: the camera moved.")
    moved_over_px: float
    cost_mm: dict[str, float] = Field(description="What the move may cost each dimension if the "
                                      "re-registration did not follow it: the support's scale at the "
                                      "part as calibrated against as now, times the dimension.")
    allowed_mm: dict[str, float] = Field(description="A third of each dimension's tolerance.")
    tolerance_from: str = Field(description="Whose tolerance: the measurement's, the verification's, "
                                "or 3 sigma when neither gives one.")
    threshold_px: float | None = Field(description="The shift whose cost reaches the allowance, px.")
    reverify: bool = Field(description="A cost over its allowance: warned, re-verification asked for.")


class StationCheckPublic(BaseModel):
    verification: StationVerificationPublic
    drift: StationDriftPublic


class ResultPublic(BaseModel):
    points: int = Field(description="Points in the cloud (a video: summed over its frames; a joint "
                        "fit: 0, it makes no cloud).")
    dimensions: DimensionsPublic
    point_loss: float = Field(description="Share of the faces' pixels not in the cloud (0 for a "
                              "joint fit).")
    warnings: list[str]
    summary: dict[str, Any] | None = Field(
        default=None, description="Videos: median, min, max, spread and std of each dimension "
                                  "over the measured frames, and each frame's values.")
    uncertainty: dict[str, float] | None = Field(
        default=None, description="One standard deviation of each dimension (width, height, "
                                  "depth), in the dimensions' unit: from the fit's covariance with "
                                  "the click and edge noise, through the scale.")
    focal_px: float | None = Field(default=None, description="The focal length used, pixels.")
    focal_source: str | None = Field(
        default=None, description="Where the focal length came from: given, camera (a calibrated "
                                  "camera), exif, pooled (fitted over the photos of one camera), "
                                  "fitted (from this box), none (square-on model).")
    fit_rms_px: float | None = Field(default=None, description="RMS distance, pixels, between the "
                                     "fitted box and the edges and clicks it was fitted to.")
    side_face: str | None = Field(default=None, description="Which face beside the front was "
                                  "measured: right, left or top.")
    quality: dict[str, Any] | None = Field(
        default=None, description="With a nominal size in the spec: the part's verdict (pass, fail, "
        "or uncertain when the measurement's interval of ±k sigma straddles a tolerance limit), "
        "counts per verdict, and per dimension (width, height, depth) nominal_mm, measured_mm, "
        "deviation_mm, tolerance_mm, sigma_mm, interval_mm and verdict. Null without a nominal.")
    points_source: str | None = Field(default=None, description="Where the reference points came "
                                      "from: clicked (given in the spec) or auto (found).")
    points_confidence: float | None = Field(
        default=None, description="Points auto: the search's confidence in the points it found, "
                                  "0-1 (below the search's threshold the item is refused; an "
                                  "accepted low one comes with a warning to check the points). "
                                  "Null for clicked points.")
    given_dimension: Literal["width", "height", "depth"] | None = Field(
        default=None, description="The dimension the scale gave rather than measured (a known "
                                  "edge, scale kind edge): its value is the length given, its "
                                  "uncertainty 0. Null otherwise.")
    reference_points: dict[str, list[float] | None] | None = Field(
        default=None, description="The reference points p1..p7 the scan used, (x, y) px.")
    joint: JointPublic | None = Field(
        default=None, description="Items with views, and videos with fit \"joint\": the views (frames) "
        "measured as ONE box: those used and those left out with the reason. The item's "
        "dimensions, uncertainty, focal_px (focal_source fitted or given), warnings and quality are "
        "the joint fit's; downloads hold its report (joint), no cloud. Null otherwise.")
    station: StationCheckPublic | None = Field(
        default=None, description="Items measured on a station: its verification's status and how far "
        "the camera moved since calibration. Null otherwise.")


class FramePublic(BaseModel):
    index: int = Field(description="The frame's index in the video (0 = the first frame).")
    state: ItemState
    error: str | None
    result: ResultPublic | None
    downloads: dict[str, str] = Field(default_factory=dict)


class ItemPublic(BaseModel):
    index: int
    state: ItemState
    error: str | None
    result: ResultPublic | None
    downloads: dict[str, str] = Field(
        default_factory=dict,
        description="Presigned GET URLs of the outputs: csv, ply, report, and preview (the cloud "
                    "decimated to at most 100,000 points, binary PLY, for display), and those of "
                    "the formats asked for (las, laz, glb; step: step (part.step) and step_meta "
                    "(part.step.json); drawing: drawing_svg, drawing_pdf, drawing_dxf); for a "
                    "video, summary (summary.json) here and each frame's files under frames; "
                    "for a joint fit, joint (joint.json: the fit's report) only.")
    frames: list[FramePublic] = Field(default_factory=list, description="A video's frames.")


_JOB_STATE = ("queued, running, then one final state: succeeded (every item succeeded), "
              "completed_with_failures (some items succeeded, at least one failed: items_failed "
              "says how many, each item its error; not a success), failed (no item succeeded, or "
              "the job itself could not go on), cancelled. Only succeeded means every item has "
              "its results.")


class JobPublic(BaseModel):
    id: str
    state: State = Field(description=_JOB_STATE)
    progress: int = Field(ge=0, le=100)
    items_done: int = Field(default=0, ge=0, description="Items finished (succeeded or failed) "
                            "so far, of item_count.")
    items_failed: int = Field(default=0, ge=0, description="Of items_done, the items that failed "
                              "(each item's error says why). A job that ended with items_failed > 0 "
                              "is never succeeded.")
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    client_reference: str | None
    webhook_url: str | None
    error: str | None
    item_count: int = Field(ge=0, description="How many items the job has; `items` holds those "
                                              "asked for with item_offset and item_limit (all by default).")
    verdicts: dict[str, int] = Field(
        default_factory=lambda: dict.fromkeys(VERDICTS, 0),
        description="How many finished items got each verdict against their nominal size: pass, "
                    "fail, uncertain (items without a nominal, and video items, are not counted).")
    items: list[ItemPublic]


class ResultsTable(BaseModel):
    """`GET /v1/jobs/{id}/results.json`: the job's table, a row per item and per video frame."""

    job_id: str
    client_reference: str | None
    state: State = Field(description="The job's state, as the job's.")
    verdicts: dict[str, int] = Field(description="As the job's: items per verdict.")
    columns: list[str] = Field(description="The rows' keys, in the CSV's column order.")
    rows: list[dict[str, Any]] = Field(description="One per item, then one per frame of a video "
                                       "item (`frame` set); null where a value is unknown.")


class JobList(BaseModel):
    """One page of `GET /v1/jobs`, newest first."""

    jobs: list[JobPublic]
    next_cursor: str | None = Field(description="Pass as `cursor` for the next page; null at the end.")


def download_name(job_id: str, index: int, kind: str, frame: int | None = None) -> str:
    """The file name a download is saved under: short job id, item (frame), the output's name."""
    where = f"item-{index}" + (f"-{frame_folder(frame)}" if frame is not None else "")
    return f"{job_id[:8]}-{where}-{FILE_NAMES.get(kind, kind)}"


def _result(result: ItemResult | None) -> ResultPublic | None:
    return ResultPublic.model_validate(result.model_dump()) if result else None


def to_public(job: JobRecord, url_for: Callable[[str, str], str],
              item_count: int | None = None) -> JobPublic:
    """The client's view of `job`; `url_for(object_key, filename)` makes each download URL.
    `item_count`: how many items the job has, when `job` holds only a page of them."""
    items = []
    for item in job.items:
        downloads = {kind: url_for(key, download_name(job.id, item.index, kind))
                     for kind, key in item.outputs.items()}
        frames = [FramePublic(index=f.index, state=ItemState(f.state.value), error=f.error,
                              result=_result(f.result),
                              downloads={kind: url_for(key, download_name(job.id, item.index, kind, f.index))
                                         for kind, key in f.outputs.items()})
                  for f in item.frames]
        items.append(ItemPublic(index=item.index, state=ItemState(item.state.value), error=item.error,
                                result=_result(item.result), downloads=downloads, frames=frames))
    return JobPublic(**job.model_dump(exclude={"items", "tenant"}), items=items,
                     item_count=len(job.items) if item_count is None else item_count)

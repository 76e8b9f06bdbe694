"""What the service remembers about a job: the durable records kept in the job store."""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Any

from pydantic import BaseModel, Field

from prismcore.spec import ScanSpec

__all__ = ["ENDED_STATES", "FINAL_STATES", "FrameRecord", "ItemRecord", "ItemResult", "ItemState",
           "ItemView", "JobRecord", "State"]


# The one state machine of a job is the store's transition script (prism_common.store), driven
# by prism_worker.lifecycle (which picks the ended state).
class State(StrEnum):
    """A job's state (and, but for `completed_with_failures`, an item's or a frame's).

    A job that ran to its end is `succeeded` when every item succeeded, `failed` when none did,
    and `completed_with_failures` when some did and some failed: `succeeded` never hides a
    failed item.
    """

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    completed_with_failures = "completed_with_failures"
    failed = "failed"
    cancelled = "cancelled"


class ItemState(StrEnum):
    """An item's or a video frame's state, as published: a job's but `completed_with_failures`."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"


# A job that ran to its end (its items decided), as opposed to one cancelled.
ENDED_STATES = frozenset({State.succeeded, State.completed_with_failures, State.failed})
FINAL_STATES = ENDED_STATES | {State.cancelled}


class ItemResult(BaseModel):
    """The measurements of one item (the rest is in its report.json).

    For a video: `dimensions` and `point_loss` are the medians over the measured frames,
    `points` their sum, and `summary` the spread of each dimension (summary.json's content).
    For a joint fit (views, or a video's frames with fit "joint"): one box's dimensions with
    their `uncertainty`, no cloud (`points` and `point_loss` 0), and `joint` (the views used and
    those left out with the reason; `ResultPublic.joint` gives its shape).
    """

    points: int
    dimensions: dict[str, float | str]
    point_loss: float
    warnings: list[str] = Field(default_factory=list)
    summary: dict[str, Any] | None = None
    uncertainty: dict[str, float] | None = None  # 1 sigma per dimension, in its unit
    focal_px: float | None = None
    focal_source: str | None = None  # given, camera, exif, pooled, fitted, none
    fit_rms_px: float | None = None
    side_face: str | None = None
    # report.json's quality block (prismcore.quality.verdicts.QualityBlock) when the spec gave a nominal
    quality: dict[str, Any] | None = None
    points_source: str | None = None  # clicked, or auto (found by the zero-click search)
    points_confidence: float | None = None  # auto: the search's confidence, 0-1
    given_dimension: str | None = None  # the dimension a known edge gave (not measured)
    reference_points: dict[str, list[float] | None] | None = None  # p1..p7 (x, y) the scan used, px
    joint: dict[str, Any] | None = None  # a joint fit: views used, left out, camera (JointPublic)
    # measured on a station: its verification's status and the camera's drift (StationCheckPublic)
    station: dict[str, Any] | None = None


class FrameRecord(BaseModel):
    """One measured frame of a video item."""

    index: int  # the frame's index in the video
    state: State
    error: str | None = None
    result: ItemResult | None = None
    outputs: dict[str, str] = Field(default_factory=dict)  # "csv"/"ply"/... -> object key


class ItemRecord(BaseModel):
    """One scan of a job: its spec (image fields are references) and what became of it."""

    index: int
    spec: ScanSpec
    file_name: str | None = None  # the name the client sent its image under (an upload's), at submit
    state: State = State.queued
    error: str | None = None
    result: ItemResult | None = None
    outputs: dict[str, str] = Field(default_factory=dict)  # "csv"/"ply"/"report" -> object key
    frames: list[FrameRecord] = Field(default_factory=list)  # a video's, in frame order


class ItemView(BaseModel):
    """One item with the facts about its job that the item's tasks need."""

    job_id: str
    tenant: str
    state: State  # the job's
    n_items: int
    item: ItemRecord


class JobRecord(BaseModel):
    id: str
    tenant: str
    state: State = State.queued
    progress: int = 0
    items_done: int = 0  # items finished (succeeded or failed), each counted once
    items_failed: int = 0  # of those, the items that failed, each counted once
    # finished items per verdict against their nominal size (pass, fail, uncertain), each once
    verdicts: dict[str, int] = Field(default_factory=lambda: {"pass": 0, "fail": 0, "uncertain": 0})
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    client_reference: str | None = None
    webhook_url: str | None = None
    error: str | None = None
    items: list[ItemRecord]

"""The worker's Celery tasks: adapters only. Each gets the process's `WorkerContext`
(`app.worker_context`), reads what Celery knows (is this a repeat? how many retries?) and calls
the logic, which lives in one place each:

* `lifecycle`: every job and item transition (start, succeed, fail, complete, end; the
  watchdog's restart and fail), and the reason a task gave up, as a client reads it;
* `steps`: an item of a photo job: plan, scan a tile, finish; or scanned whole;
* `joint_item`: several views of one part (an item's views, a video's frames with fit
  "joint") measured as ONE box, whole in one task;
* `station_item`: a photo measured on a stored station (no points, no scale), whole in one task;
* `video`: a video item split into frames, a frame measured, the item summarised; an uploaded
  video's frame extracted for the web page;
* `upload_points`: the box and its points found in an upload, for the web page;
* `inputs` (references, fetch, egress), `artifacts` (object keys, plan.json, tiles, outputs,
  caches), `webhooks`, `watchdog` (stall sweep, retention), `broker` (kombu's structures).

Graph: run_job -> plan_item (a window of items per job) -> chord(scan_tile per face band)
-> finish_item -> the next plan_item, and after the job's last item deliver_webhook. An item
of a batch (one tile per face) is scanned whole inside plan_item instead. A video item's
plan_item splits it and sends a scan_frame task per frame as it goes (a long split hands the
rest of its frames on to split_video, part after part); the last frame summarises the item and
completes it. Apart from jobs, extract_frame probes an uploaded video and stores
one frame for the web page to mark, and find_points searches an upload for the box and its
points (both on the frames queue). Tasks pass ids and object keys only; each is
idempotent (deterministic keys, exists-checks, counting by set membership), since late acks
redo a task whose worker was lost.

Errors: bad input fails its item only. Store and broker trouble is retried with back-off;
when the retries run out the item fails with the reason (`lifecycle.failure_reason`), so no job
runs forever.
"""

from __future__ import annotations

import logging
import random
from collections.abc import Callable
from datetime import datetime
from typing import TYPE_CHECKING, Any

import httpx
import redis
from botocore.exceptions import BotoCoreError, ClientError
from celery import Task, chord
from celery.exceptions import Retry
from prism_common.queue import (
    TASK_DELIVER_WEBHOOK,
    TASK_EXTRACT_FRAME,
    TASK_FIND_POINTS,
    TASK_FINISH_ITEM,
    TASK_PLAN_ITEM,
    TASK_RUN_JOB,
    TASK_SCAN_FRAME,
    TASK_SCAN_TILE,
    TASK_SPLIT_VIDEO,
)
from prism_common.records import ItemResult, ItemView, State
from prism_common.references import ReferenceError

from prismcore import InputError
from prismcore.spec import ItemKind

from . import joint_item, lifecycle, station_item, steps, upload_points, video, webhooks
from .app import app, worker_context
from .artifacts import tile_id
from .context import WorkerContext
from .inputs import FetchError

__all__ = ["deliver_webhook", "extract_frame", "find_points", "finish_item", "plan_item", "run_job",
           "scan_frame", "scan_tile", "split_video"]

log = logging.getLogger(__name__)

if TYPE_CHECKING:  # Task is generic in its stubs (celery-types), not at run time
    AnyTask = Task[Any, Any]
else:
    AnyTask = Task

RETRYABLE = (BotoCoreError, ClientError, redis.ConnectionError, redis.TimeoutError)
INPUT_ERRORS = (InputError, ReferenceError, FetchError)  # the item's own fault: never retried


RETRIES = 5
RETRY_BACKOFF_S = 5


def retry_caps_s(visibility_timeout_s: int) -> list[int]:
    """The longest wait (s) before each retry: 5, 10, 20, 40, 80 s, at most half the visibility
    timeout (a retry waits as an unacked message: past that timeout the broker would hand out a
    second copy)."""
    top = max(1, min(600, visibility_timeout_s // 2))
    return [min(top, RETRY_BACKOFF_S * 2**n) for n in range(RETRIES)]


def retry_window_s(visibility_timeout_s: int) -> float:
    """How long an outage (object store, Redis) every task is sure to ride out: each wait is at
    least half its cap, so the last retry comes no sooner than this after the first failure
    (77.5 s with the default 300 s visibility timeout)."""
    return sum(retry_caps_s(visibility_timeout_s)) / 2


class RetryingTask(AnyTask):
    """Waits before each of `RETRIES` retries drawn between half and all of `retry_caps_s`
    ("equal jitter"): retries of many tasks spread out, yet an outage shorter than
    `retry_window_s` is ridden out whatever the draw (Celery's full jitter may draw five waits
    near 0 s and give up within seconds: seen when a loaded machine restarted the store). Late
    acks are app-wide (prism_common.queue)."""

    retry_backoff = RETRY_BACKOFF_S
    retry_jitter = False  # the exact cap; `retry` draws the wait from its upper half

    @property
    def retry_backoff_max(self) -> int:
        return retry_caps_s(worker_context().settings.visibility_timeout_s)[-1]

    def retry(self, args: tuple[Any, ...] | None = None, kwargs: dict[str, Any] | None = None,
              exc: Exception | None = None, throw: bool = True, eta: datetime | None = None,
              countdown: float | None = None, max_retries: int | None = None, **options: Any) -> Retry:
        if countdown is not None:
            countdown = countdown * random.uniform(0.5, 1.0)
        return super().retry(args, kwargs, exc, throw, eta, countdown, max_retries, **options)


def _maybe_repeat(task: AnyTask) -> bool:
    """Did an earlier run of this very task possibly get part way (retry or redelivery)?"""
    delivery = task.request.delivery_info or {}
    return bool(task.request.retries or delivery.get("redelivered"))


def _reason(task: AnyTask, exc: BaseException) -> str:
    return lifecycle.failure_reason(exc, task.request.retries, task.soft_time_limit)


class ItemTask(RetryingTask):
    """A task about one item: if it fails for good, the item fails and the job goes on."""

    job_arg = 0  # where job_id is in the task's args; the item index follows it

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        job_id, item = args[self.job_arg], args[self.job_arg + 1]
        tile = tile_id(*args[2:5]) if self.name == TASK_SCAN_TILE else None
        log.error("item %s/%s failed for good in %s: %r", job_id, item, self.name, exc)
        try:
            lifecycle.fail_and_complete(worker_context(), job_id, item, _reason(self, exc),
                                        maybe_repeat=True, tile=tile)
        except Exception:
            log.exception("could not record the failure of item %s/%s", job_id, item)


class JobTask(RetryingTask):
    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        try:
            lifecycle.job_failed(worker_context(), args[0], _reason(self, exc))
        except Exception:
            log.exception("could not record the failure of job %s", args[0])


class FrameTask(RetryingTask):
    """A task about one frame: if it fails for good, the frame fails and the item goes on."""

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        job_id, item, frame = args[:3]
        log.error("frame %s of item %s/%s failed for good: %r", frame, job_id, item, exc)
        try:
            ctx = worker_context()
            video.frame_failed(ctx, job_id, item, frame, _reason(self, exc))
            video.frame_finished(ctx, job_id, item, frame, maybe_repeat=True)
        except Exception:
            log.exception("could not record the failure of frame %s of %s/%s", frame, job_id, item)


@app.task(name=TASK_RUN_JOB, base=JobTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES,
          ignore_result=True)
def run_job(self: AnyTask, job_id: str) -> None:
    lifecycle.start_job(worker_context(), job_id, maybe_repeat=_maybe_repeat(self))


@app.task(name=TASK_PLAN_ITEM, base=ItemTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES,
          ignore_result=True)
def plan_item(self: AnyTask, job_id: str, item: int) -> None:
    ctx, repeat = worker_context(), _maybe_repeat(self)
    view = lifecycle.open_item(ctx, job_id, item, repeat=repeat)
    if view is None:
        return
    lifecycle.mark_running(ctx, view, repeat=repeat)
    PLANS[view.item.spec.kind](ctx, view, repeat)


def _plan_photo(ctx: WorkerContext, view: ItemView, repeat: bool) -> None:
    """A photo: scanned whole in this task when the job's items have one tile per face (a
    batch), else planned into tiles."""
    if steps.tiles_per_face(ctx, view.n_items) == 1:
        _scan_whole(ctx, view, repeat)
    else:
        _plan_tiles(ctx, view, repeat)


def _plan_joint(ctx: WorkerContext, view: ItemView, repeat: bool) -> None:
    _scan_whole(ctx, view, repeat, joint_item.measure_joint)


def _plan_station(ctx: WorkerContext, view: ItemView, repeat: bool) -> None:
    _scan_whole(ctx, view, repeat, station_item.measure_station)


def _plan_tiles(ctx: WorkerContext, view: ItemView, repeat: bool) -> None:
    """A tiled item: plan it, then a chord of its tiles whose callback finishes it."""
    job_id, item = view.job_id, view.item.index
    try:
        tiles = steps.plan_item(ctx, view)
    except INPUT_ERRORS as exc:
        lifecycle.fail_and_complete(ctx, job_id, item, str(exc), maybe_repeat=repeat)
        return
    lifecycle.count_plan(ctx, job_id, item, len(tiles))
    # The finish runs when every tile has; this task does not wait for them.
    chord(scan_tile.s(job_id, item, *tile) for tile in tiles)(finish_item.s(job_id, item))


def _split_video(ctx: WorkerContext, view: ItemView, repeat: bool, part: int = 0) -> None:
    """A video: its frames are stored and sent as scan_frame tasks; the last one finishes it."""
    try:
        video.split_video(ctx, view, part)
    except INPUT_ERRORS as exc:
        lifecycle.fail_and_complete(ctx, view.job_id, view.item.index, str(exc), maybe_repeat=repeat)


Plan = Callable[[WorkerContext, ItemView, bool], None]

PLANS: dict[ItemKind, Plan] = {
    "photo": _plan_photo, "found": _plan_photo,  # the search runs in the item's plan
    "video": _split_video, "tracked": _split_video,  # a scan_frame task per frame
    "tracked_joint": _plan_joint, "frames_joint": _plan_joint, "views": _plan_joint,  # one box
    "station": _plan_station,
}
"""What plan_item does with an item of each kind: the one place the worker tells the kinds apart."""


@app.task(name=TASK_SPLIT_VIDEO, base=ItemTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES,
          ignore_result=True)
def split_video(self: AnyTask, job_id: str, item: int, part: int) -> None:
    """The rest of a video's split, from where the part before it stopped (its time was up)."""
    ctx, repeat = worker_context(), _maybe_repeat(self)
    view = lifecycle.open_item(ctx, job_id, item, repeat=repeat)
    if view is not None:
        _split_video(ctx, view, repeat, part)


Measure = Callable[[WorkerContext, ItemView], tuple[ItemResult, dict[str, str]]]


def _scan_whole(ctx: WorkerContext, view: ItemView, repeat: bool,
                measure: Measure = steps.scan_whole_item) -> None:
    """A batch item (or a joint fit's views): plan, scan and finish here (no tiles, nothing
    stored on the way)."""
    job_id, item = view.job_id, view.item.index
    try:
        result, outputs = measure(ctx, view)
    except INPUT_ERRORS as exc:
        lifecycle.fail_and_complete(ctx, job_id, item, str(exc), maybe_repeat=repeat)
        return
    lifecycle.count_plan(ctx, job_id, item, 0)
    if ctx.store.state(job_id) != State.running:
        return  # cancelled meanwhile: leave the item as it was
    lifecycle.succeed_item(ctx, job_id, view.item, result, outputs)
    lifecycle.complete_item(ctx, job_id, item, maybe_repeat=repeat)


@app.task(name=TASK_SCAN_TILE, base=ItemTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES)
def scan_tile(self: AnyTask, job_id: str, item: int, face: str, r0: int, r1: int) -> str | None:
    ctx = worker_context()
    if ctx.store.state(job_id) != State.running:
        return None
    key = steps.scan_tile(ctx, job_id, item, face, r0, r1)
    ctx.store.tile_done(job_id, item, tile_id(face, r0, r1))
    return key


@app.task(name=TASK_SCAN_FRAME, base=FrameTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES,
          ignore_result=True)
def scan_frame(self: AnyTask, job_id: str, item: int, frame: int) -> None:
    ctx, repeat = worker_context(), _maybe_repeat(self)
    view = lifecycle.open_item(ctx, job_id, item, repeat=repeat)
    if view is None:
        return
    video.scan_frame(ctx, view, frame)
    video.frame_finished(ctx, job_id, item, frame, maybe_repeat=repeat)


@app.task(name=TASK_FINISH_ITEM, base=ItemTask, bind=True, job_arg=1, ignore_result=True, max_retries=RETRIES,
          autoretry_for=(*RETRYABLE, steps.TilesMissingError))
def finish_item(self: AnyTask, tile_keys: list[str | None], job_id: str, item: int) -> None:
    # tile_keys (the chord's results) are not needed: plan.json lists the tiles to merge.
    ctx, repeat = worker_context(), _maybe_repeat(self)
    view = ctx.store.get_item(job_id, item)
    lifecycle.complete_if_ended(ctx, view, repeat=repeat)  # see lifecycle.open_item
    if view is None or view.state != State.running:
        return
    record = view.item
    if record.state not in (State.succeeded, State.failed):  # else a repeat: only complete it
        try:
            result, outputs = steps.finish_item(ctx, job_id, item)
        except InputError as exc:  # e.g. a cloud over the spec's max_points
            lifecycle.fail_item(ctx, job_id, item, str(exc))
        else:
            lifecycle.succeed_item(ctx, job_id, record, result, outputs)
    lifecycle.complete_item(ctx, job_id, item, maybe_repeat=repeat)


class WebhookTask(RetryingTask):
    """A delivery: given up for good after its retries, it is no longer due (else the
    watchdog, which re-sends deliveries lost with the broker, would send it for ever)."""

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        log.error("webhook of job %s given up: %r", args[0], exc)
        try:
            worker_context().store.webhook_done(args[0])
        except Exception:
            log.exception("could not mark the webhook of job %s given up", args[0])


@app.task(name=TASK_DELIVER_WEBHOOK, base=WebhookTask, bind=True, ignore_result=True, max_retries=8,
          autoretry_for=(*RETRYABLE, webhooks.WebhookError, httpx.HTTPError))
def deliver_webhook(self: AnyTask, job_id: str) -> None:
    ctx = worker_context()
    try:
        webhooks.deliver(ctx, job_id)
    except ReferenceError as exc:  # a URL we may not call will not become callable: no retry
        log.warning("webhook of job %s not sent: %s", job_id, exc)
    try:
        ctx.store.webhook_done(job_id)
    except redis.RedisError as exc:  # not a reason to post it again now: the watchdog may, later
        log.warning("webhook of job %s delivered, but not marked so: %r", job_id, exc)


@app.task(name=TASK_EXTRACT_FRAME, base=RetryingTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES,
          ignore_result=True)
def extract_frame(self: AnyTask, upload_id: str, frame: int) -> None:
    video.extract_frame(worker_context(), upload_id, frame)


def _hint(hint: list[int] | None) -> tuple[int, int] | None:
    return None if hint is None else (int(hint[0]), int(hint[1]))


class PointsTask(RetryingTask):
    """A point search: if it fails for good, its answer says why (the page is waiting on it)."""

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        upload_id, frame, hint = args[:3]
        log.error("point search in upload %s failed for good: %r", upload_id, exc)
        try:
            upload_points.search_failed(worker_context(), upload_id, frame, _hint(hint), _reason(self, exc))
        except Exception:
            log.exception("could not record the failed point search in upload %s", upload_id)


@app.task(name=TASK_FIND_POINTS, base=PointsTask, bind=True, autoretry_for=RETRYABLE, max_retries=RETRIES,
          ignore_result=True)
def find_points(self: AnyTask, upload_id: str, frame: int | None, hint: list[int] | None) -> None:
    upload_points.find_upload_points(worker_context(), upload_id, frame, _hint(hint))

"""The worker's tasks, thin like web views: check the job, call the module that does the work.

Graph: run_job -> plan_item (a window of items per job) -> chord(scan_tile per face band)
-> finish_item -> the next plan_item, and after the job's last item deliver_webhook. An item
of a batch (one tile per face) is scanned whole inside plan_item instead (`whole_item`). A
video item's plan_item splits it (`video_item`) and sends a scan_frame task per frame as it
goes; the last frame summarises the item and completes it (`frame_scan`). Apart from jobs,
extract_frame probes an uploaded video and stores one frame for the web page to mark
(`upload_frames`, own queue). Tasks pass ids and object keys only; each is idempotent
(deterministic keys, exists-checks, counting by set membership), since late acks redo a task
whose worker was lost.

Errors: bad input fails its item only. Store and broker trouble is retried with back-off;
when the retries run out the item fails with the reason (reasons.py), so no job runs forever.
"""

from __future__ import annotations

import logging
from typing import Any

import httpx
import redis
from botocore.exceptions import BotoCoreError, ClientError
from celery import Task, chord
from prism_common.queue import (
    TASK_DELIVER_WEBHOOK,
    TASK_EXTRACT_FRAME,
    TASK_FINISH_ITEM,
    TASK_PLAN_ITEM,
    TASK_RUN_JOB,
    TASK_SCAN_FRAME,
    TASK_SCAN_TILE,
)
from prism_common.records import ItemView, State
from prism_common.references import ReferenceError

from prismcore import InputError

from . import (
    context,
    fanout,
    frame_scan,
    planning,
    reasons,
    scanning,
    timing,
    upload_frames,
    video_item,
    webhooks,
    whole_item,
)
from .app import app
from .fetch import FetchError
from .keys import tile_id

__all__ = ["deliver_webhook", "extract_frame", "finish_item", "plan_item", "run_job", "scan_frame",
           "scan_tile"]

log = logging.getLogger(__name__)
assert timing  # imported for its signal handlers (task durations)

RETRYABLE = (BotoCoreError, ClientError, redis.ConnectionError, redis.TimeoutError)
# A retry waits as an unacked message: past the visibility timeout the broker would hand out a
# second copy, so back-off stays below it.
BACKOFF_MAX = max(1, min(600, context.settings().visibility_timeout_s // 2))
# Waits of up to 5, 10, 20, 40, 80 s (random below each: retries of many tasks spread out), so
# five retries ride out a store restarting, not only a dropped connection.
_RETRY = {"bind": True, "retry_backoff": 5,  # late acks: app-wide (prism_common.queue)
          "retry_backoff_max": BACKOFF_MAX, "retry_jitter": True}


def _maybe_repeat(task: Task) -> bool:
    """Did an earlier run of this very task possibly get part way (retry or redelivery)?"""
    delivery = task.request.delivery_info or {}
    return bool(task.request.retries or delivery.get("redelivered"))


def _open_item(job_id: str, item: int, *, repeat: bool) -> ItemView | None:
    """The item, if its job is running and the item has no outcome yet; else None.

    A repeat that finds the job ended completes the item again: the run that ended the job may
    have died between moving its state and writing job.json, and nothing else would redo that.
    """
    view = context.store().get_item(job_id, item)
    _complete_if_ended(view, repeat)
    if view is None or view.state != State.running or view.item.state in (State.succeeded,
                                                                          State.failed):
        return None
    return view


def _complete_if_ended(view: ItemView | None, repeat: bool) -> None:
    if view is not None and repeat and view.state in (State.succeeded, State.failed):
        fanout.complete_item(view.job_id, view.item.index, maybe_repeat=True)


def _running(job_id: str) -> bool:
    return context.store().state(job_id) == State.running


class ItemTask(Task):
    """A task about one item: if it fails for good, the item fails and the job goes on."""

    job_arg = 0  # where job_id is in the task's args; the item index follows it

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        job_id, item = args[self.job_arg], args[self.job_arg + 1]
        tile = tile_id(*args[2:5]) if self.name == TASK_SCAN_TILE else None
        message = reasons.failure_reason(exc, self.request.retries, self.soft_time_limit)
        log.error("item %s/%s failed for good in %s: %r", job_id, item, self.name, exc)
        try:
            fanout.fail_item(job_id, item, message, tile=tile)
            fanout.complete_item(job_id, item, maybe_repeat=True)
        except Exception:
            log.exception("could not record the failure of item %s/%s", job_id, item)


class JobTask(Task):
    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        try:
            reason = reasons.failure_reason(exc, self.request.retries, self.soft_time_limit)
            context.store().transition(args[0], State.failed, error=reason)
        except Exception:
            log.exception("could not record the failure of job %s", args[0])


@app.task(name=TASK_RUN_JOB, base=JobTask, autoretry_for=RETRYABLE, max_retries=5,
          ignore_result=True, **_RETRY)
def run_job(self: Task, job_id: str) -> None:
    fanout.start_job(job_id, maybe_repeat=_maybe_repeat(self))


@app.task(name=TASK_PLAN_ITEM, base=ItemTask, autoretry_for=RETRYABLE, max_retries=5,
          ignore_result=True, **_RETRY)
def plan_item(self: Task, job_id: str, item: int) -> None:
    repeat = _maybe_repeat(self)
    view = _open_item(job_id, item, repeat=repeat)
    if view is None:
        return
    if not repeat and view.item.state == State.queued:
        # Only a first run marks it: a repeat could race the item's own finish and undo it.
        view.item = view.item.model_copy(update={"state": State.running})
        context.store().put_item(job_id, view.item)
    if view.item.spec.is_video:
        _split_video(view, repeat)
        return
    if planning.tiles_per_face(view.n_items) == 1:
        _scan_whole(view, repeat)
        return
    try:
        tiles = planning.plan_item(view)
    except (InputError, ReferenceError, FetchError) as exc:
        fanout.fail_item(job_id, item, str(exc))
        fanout.complete_item(job_id, item, maybe_repeat=repeat)
        return
    fanout.count_plan(job_id, item, len(tiles))
    # The finish runs when every tile has; this task does not wait for them.
    chord(scan_tile.s(job_id, item, *tile) for tile in tiles)(finish_item.s(job_id, item))


def _split_video(view: ItemView, repeat: bool) -> None:
    """A video: its frames are stored and sent as scan_frame tasks; the last one finishes it."""
    try:
        video_item.split_video(view)
    except (InputError, ReferenceError, FetchError) as exc:
        fanout.fail_item(view.job_id, view.item.index, str(exc))
        fanout.complete_item(view.job_id, view.item.index, maybe_repeat=repeat)


def _scan_whole(view: ItemView, repeat: bool) -> None:
    """A batch item: plan, scan and finish here (no tiles, nothing stored on the way)."""
    job_id, item = view.job_id, view.item.index
    try:
        result, outputs = whole_item.scan_whole_item(view)
    except (InputError, ReferenceError, FetchError) as exc:
        fanout.fail_item(job_id, item, str(exc))
    else:
        fanout.count_plan(job_id, item, 0)
        if not _running(job_id):
            return  # cancelled meanwhile: leave the item as it was
        fanout.succeed_item(job_id, view.item, result, outputs)
    fanout.complete_item(job_id, item, maybe_repeat=repeat)


@app.task(name=TASK_SCAN_TILE, base=ItemTask, autoretry_for=RETRYABLE, max_retries=5, **_RETRY)
def scan_tile(self: Task, job_id: str, item: int, face: str, r0: int, r1: int) -> str | None:
    if not _running(job_id):
        return None
    key = scanning.scan_tile(job_id, item, face, r0, r1)
    context.store().tile_done(job_id, item, tile_id(face, r0, r1))
    return key


class FrameTask(Task):
    """A task about one frame: if it fails for good, the frame fails and the item goes on."""

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        job_id, item, frame = args[:3]
        log.error("frame %s of item %s/%s failed for good: %r", frame, job_id, item, exc)
        try:
            frame_scan.frame_failed(job_id, item, frame,
                                    reasons.failure_reason(exc, self.request.retries, self.soft_time_limit))
            frame_scan.frame_finished(job_id, item, frame, maybe_repeat=True)
        except Exception:
            log.exception("could not record the failure of frame %s of %s/%s", frame, job_id, item)


@app.task(name=TASK_SCAN_FRAME, base=FrameTask, autoretry_for=RETRYABLE, max_retries=5,
          ignore_result=True, **_RETRY)
def scan_frame(self: Task, job_id: str, item: int, frame: int) -> None:
    repeat = _maybe_repeat(self)
    view = _open_item(job_id, item, repeat=repeat)
    if view is None:
        return
    frame_scan.scan_frame(view, frame)
    frame_scan.frame_finished(job_id, item, frame, maybe_repeat=repeat)


@app.task(name=TASK_FINISH_ITEM, base=ItemTask, job_arg=1, ignore_result=True, max_retries=5,
          autoretry_for=(*RETRYABLE, scanning.TilesMissingError), **_RETRY)
def finish_item(self: Task, tile_keys: list[str | None], job_id: str, item: int) -> None:
    # tile_keys (the chord's results) are not needed: plan.json lists the tiles to merge.
    repeat = _maybe_repeat(self)
    view = context.store().get_item(job_id, item)
    _complete_if_ended(view, repeat)  # see _open_item
    if view is None or view.state != State.running:
        return
    record = view.item
    if record.state not in (State.succeeded, State.failed):  # else a repeat: only complete it
        try:
            result, outputs = scanning.finish_item(job_id, item)
        except InputError as exc:  # e.g. a cloud over the spec's max_points
            fanout.fail_item(job_id, item, str(exc))
        else:
            fanout.succeed_item(job_id, record, result, outputs)
    fanout.complete_item(job_id, item, maybe_repeat=repeat)


@app.task(name=TASK_DELIVER_WEBHOOK, ignore_result=True, max_retries=8,
          autoretry_for=(*RETRYABLE, webhooks.WebhookError, httpx.HTTPError), **_RETRY)
def deliver_webhook(self: Task, job_id: str) -> None:
    try:
        webhooks.deliver(job_id)
    except ReferenceError as exc:  # a URL we may not call will not become callable: no retry
        log.warning("webhook of job %s not sent: %s", job_id, exc)


@app.task(name=TASK_EXTRACT_FRAME, autoretry_for=RETRYABLE, max_retries=5, ignore_result=True, **_RETRY)
def extract_frame(self: Task, upload_id: str, frame: int) -> None:
    upload_frames.extract_frame(upload_id, frame)

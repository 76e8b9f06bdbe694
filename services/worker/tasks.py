"""The worker's tasks, thin like web views: check the job, call the module that does the work.

Graph: run_job -> plan_item (a window of items per job) -> chord(scan_tile per face band)
-> finish_item -> the next plan_item, and after the job's last item deliver_webhook. Tasks
pass ids and object keys only; each is idempotent (deterministic keys, exists-checks,
counting by set membership), since late acks redo a task whose worker was lost.

Errors: bad input fails its item only. Store and broker trouble is retried with back-off;
when the retries run out the item fails with "internal error", so no job runs forever.
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
    TASK_FINISH_ITEM,
    TASK_PLAN_ITEM,
    TASK_RUN_JOB,
    TASK_SCAN_TILE,
)
from prism_common.records import State
from prism_common.references import ReferenceError

from prismcore import InputError

from . import context, fanout, planning, scanning, timing, webhooks
from .app import app
from .fetch import FetchError
from .keys import tile_id

__all__ = ["deliver_webhook", "finish_item", "plan_item", "run_job", "scan_tile"]

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


def _running(job_id: str) -> bool:
    return context.store().state(job_id) == State.running


class ItemTask(Task):
    """A task about one item: if it fails for good, the item fails and the job goes on."""

    job_arg = 0  # where job_id is in the task's args; the item index follows it

    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        job_id, item = args[self.job_arg], args[self.job_arg + 1]
        tile = tile_id(*args[2:5]) if self.name == TASK_SCAN_TILE else None
        # The class name, not the message: that may name internal hosts.
        retries = self.request.retries
        message = f"internal error: {type(exc).__name__}" + (f" after {retries} retries" if retries else "")
        log.error("item %s/%s failed for good in %s: %r", job_id, item, self.name, exc)
        try:
            fanout.fail_item(job_id, item, message, tile=tile)
            fanout.complete_item(job_id, item, maybe_repeat=True)
        except Exception:
            log.exception("could not record the failure of item %s/%s", job_id, item)


class JobTask(Task):
    def on_failure(self, exc: Exception, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        try:
            context.store().transition(args[0], State.failed,
                                       error=f"internal error: {type(exc).__name__}")
        except Exception:
            log.exception("could not record the failure of job %s", args[0])


@app.task(name=TASK_RUN_JOB, base=JobTask, autoretry_for=RETRYABLE, max_retries=5,
          ignore_result=True, **_RETRY)
def run_job(self: Task, job_id: str) -> None:
    fanout.start_job(job_id, maybe_repeat=_maybe_repeat(self))


@app.task(name=TASK_PLAN_ITEM, base=ItemTask, autoretry_for=RETRYABLE, max_retries=5,
          ignore_result=True, **_RETRY)
def plan_item(self: Task, job_id: str, item: int) -> None:
    job = context.store().get(job_id)
    if job is None or job.state != State.running or job.items[item].state in (State.succeeded,
                                                                            State.failed):
        return
    repeat = _maybe_repeat(self)
    if not repeat and job.items[item].state == State.queued:
        # Only a first run marks it: a repeat could race the item's own finish and undo it.
        context.store().put_item(job_id, job.items[item].model_copy(update={"state": State.running}))
    try:
        tiles = planning.plan_item(job, item)
    except (InputError, ReferenceError, FetchError) as exc:
        fanout.fail_item(job_id, item, str(exc))
        fanout.complete_item(job_id, item, maybe_repeat=repeat)
        return
    fanout.count_plan(job_id, item, len(tiles))
    # The finish runs when every tile has; this task does not wait for them.
    chord(scan_tile.s(job_id, item, *tile) for tile in tiles)(finish_item.s(job_id, item))


@app.task(name=TASK_SCAN_TILE, base=ItemTask, autoretry_for=RETRYABLE, max_retries=5, **_RETRY)
def scan_tile(self: Task, job_id: str, item: int, face: str, r0: int, r1: int) -> str | None:
    if not _running(job_id):
        return None
    key = scanning.scan_tile(job_id, item, face, r0, r1)
    context.store().tile_done(job_id, item, tile_id(face, r0, r1))
    return key


@app.task(name=TASK_FINISH_ITEM, base=ItemTask, job_arg=1, ignore_result=True, max_retries=5,
          autoretry_for=(*RETRYABLE, scanning.TilesMissingError), **_RETRY)
def finish_item(self: Task, tile_keys: list[str | None], job_id: str, item: int) -> None:
    # tile_keys (the chord's results) are not needed: plan.json lists the tiles to merge.
    job = context.store().get(job_id)
    if job is None or job.state != State.running:
        return
    record = job.items[item]
    if record.state not in (State.succeeded, State.failed):  # else a repeat: only complete it
        try:
            result, outputs = scanning.finish_item(job_id, item)
        except InputError as exc:  # e.g. a cloud over the spec's max_points
            fanout.fail_item(job_id, item, str(exc))
        else:
            fanout.succeed_item(job_id, record, result, outputs)
    fanout.complete_item(job_id, item, maybe_repeat=_maybe_repeat(self))


@app.task(name=TASK_DELIVER_WEBHOOK, ignore_result=True, max_retries=8,
          autoretry_for=(*RETRYABLE, webhooks.WebhookError, httpx.HTTPError), **_RETRY)
def deliver_webhook(self: Task, job_id: str) -> None:
    try:
        webhooks.deliver(job_id)
    except ReferenceError as exc:  # a URL we may not call will not become callable: no retry
        log.warning("webhook of job %s not sent: %s", job_id, exc)

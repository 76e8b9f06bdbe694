"""Every transition of a job and of its items, in one place: start, succeed, fail, complete,
end, and the watchdog's restart and fail.

A job's items run in a window: `start_job` starts the first `items_in_flight_per_job`, and each
item that completes starts the next, until the last one ends the job (succeeded if every item
did, failed if none did, completed_with_failures if some did and some failed), which writes
job.json and sends the webhook. An item has an outcome
(`succeed_item`, `fail_item`) and is then completed (`complete_item`); `fail_and_complete` is
the two together, what every step does when its item cannot go on.

Progress is counted in units: an item is 1 (plan) + its tiles + 1 (complete); until it is
planned it is taken to be as big as the planned items on average (`prism_common.store.progress`).
The plan and complete units are counted through the store's set of finished tiles (as "plan"
and "complete"), so a task that runs twice counts once; the "complete" entry also tells
whether this is the item's first completion.

A task that may be a repeat (`maybe_repeat`: redelivered after a lost worker, or retried after
an error part way) refills the window even if an earlier run may have: starting one item too
many is harmless (each index is claimed once), starting one too few could stall the job
forever. Restarts (the watchdog's) re-send the tasks that would have come next; tasks are
idempotent (deterministic keys, exists-checks, counting by set membership), so re-sending work
that did in fact happen writes the same objects again and counts nothing twice.
"""

from __future__ import annotations

import logging

import redis
from billiard.exceptions import SoftTimeLimitExceeded, TimeLimitExceeded
from botocore.exceptions import ClientError, ConnectionError, HTTPClientError
from prism_common.queue import TASK_DELIVER_WEBHOOK, TASK_FINISH_ITEM, TASK_PLAN_ITEM, TASK_RUN_JOB
from prism_common.records import (
    ENDED_STATES,
    FINAL_STATES,
    ItemRecord,
    ItemResult,
    ItemView,
    JobRecord,
    State,
)
from prism_common.store import UNITS_PER_ITEM_ESTIMATE

from .artifacts import job_key
from .context import WorkerContext

__all__ = ["complete_if_ended", "complete_item", "count_plan", "ended_state", "fail_and_complete",
           "fail_item", "fail_job", "failure_reason", "job_failed", "mark_running", "open_item",
           "restart_job", "start_items", "start_job", "succeed_item"]

log = logging.getLogger(__name__)

_DECIDED = (State.succeeded, State.failed)  # an item's outcome


# -- jobs ---------------------------------------------------------------------------------------
def start_job(ctx: WorkerContext, job_id: str, *, maybe_repeat: bool) -> None:
    """Move a queued job to running and start its first window of items."""
    job = ctx.store.get(job_id)
    if job is None or job.state not in (State.queued, State.running):
        return
    if not ctx.store.transition(job_id, State.running) and not maybe_repeat:
        return  # another delivery of run_job started it
    n = len(job.items)
    if n == 0:  # nothing will ever complete to end it
        _end_job(ctx, job, maybe_repeat=maybe_repeat)
        return
    start_items(ctx, job_id, n, min(ctx.settings.items_in_flight_per_job, n))


def start_items(ctx: WorkerContext, job_id: str, n_items: int, count: int) -> None:
    """Claim and start up to `count` more of the job's items."""
    for _ in range(count):
        i = ctx.store.next_item(job_id)
        if i >= n_items:
            return
        ctx.send_task(TASK_PLAN_ITEM, (job_id, i))


def job_failed(ctx: WorkerContext, job_id: str, reason: str) -> None:
    """A job-level task gave up: the job fails with the reason (its items stay as they are),
    and its client is told, as for a job that ends by itself."""
    if ctx.store.transition(job_id, State.failed, error=reason):
        job = ctx.store.get(job_id)
        if job is not None and job.webhook_url:
            ctx.send_task(TASK_DELIVER_WEBHOOK, (job_id,))


def ended_state(job: JobRecord) -> tuple[State, str | None]:
    """The state a job whose items are all done ends in, and its error: succeeded when every
    item succeeded, failed when none did, completed_with_failures (naming how many failed) when
    some did and some did not."""
    n = len(job.items)
    ok = sum(item.state == State.succeeded for item in job.items)
    if ok == 0:
        return State.failed, "all items failed"
    if ok == n:
        return State.succeeded, None
    return State.completed_with_failures, f"{n - ok} of {n} items failed"


def _end_job(ctx: WorkerContext, job: JobRecord, *, maybe_repeat: bool) -> None:
    """Every item is done: the job ends as `ended_state` says; then job.json, webhook."""
    state, error = ended_state(job)
    moved = ctx.store.transition(job.id, state, error=error)
    if not (moved or maybe_repeat):
        return  # the job had already ended: whoever ended it wrote job.json
    final = ctx.store.get(job.id)
    if final is None or final.state not in ENDED_STATES:
        return  # cancelled at the last moment
    _write_job_document(ctx, final)
    if final.webhook_url:
        ctx.send_task(TASK_DELIVER_WEBHOOK, (job.id,))


def _write_job_document(ctx: WorkerContext, job: JobRecord) -> None:
    ctx.objects.put_bytes(job_key(job.id, "job.json"), (job.model_dump_json(indent=2) + "\n").encode(),
                          "application/json")


# -- items --------------------------------------------------------------------------------------
def open_item(ctx: WorkerContext, job_id: str, item: int, *, repeat: bool) -> ItemView | None:
    """The item, if its job is running and the item has no outcome yet; else None.

    A repeat that finds the job ended completes the item again: the run that ended the job may
    have died between moving its state and writing job.json, and nothing else would redo that.
    """
    view = ctx.store.get_item(job_id, item)
    complete_if_ended(ctx, view, repeat=repeat)
    if view is None or view.state != State.running or view.item.state in _DECIDED:
        return None
    return view


def complete_if_ended(ctx: WorkerContext, view: ItemView | None, *, repeat: bool) -> None:
    """See `open_item`: a repeat about an ended job completes its item again."""
    if view is not None and repeat and view.state in ENDED_STATES:
        complete_item(ctx, view.job_id, view.item.index, maybe_repeat=True)


def mark_running(ctx: WorkerContext, view: ItemView, *, repeat: bool) -> None:
    """A queued item starts running. Only a first run marks it: a repeat could race the item's
    own finish and undo it."""
    if not repeat and view.item.state == State.queued:
        view.item = view.item.model_copy(update={"state": State.running})
        ctx.store.put_item(view.job_id, view.item)


def count_plan(ctx: WorkerContext, job_id: str, item: int, tiles: int) -> None:
    """Count the plan's unit and replace the item's estimate by its real size, once."""
    ctx.store.tile_done(job_id, item, "plan", total=tiles + 2 - UNITS_PER_ITEM_ESTIMATE, planned=1)


def succeed_item(ctx: WorkerContext, job_id: str, record: ItemRecord, result: ItemResult,
                 outputs: dict[str, str]) -> None:
    ctx.store.put_item(job_id, record.model_copy(
        update={"state": State.succeeded, "error": None, "result": result, "outputs": outputs}))


def fail_item(ctx: WorkerContext, job_id: str, item: int, message: str, *, tile: str | None = None) -> None:
    """Record the item's failure (unless it already has an outcome) and count its units."""
    store = ctx.store
    if store.state(job_id) is None:
        return  # counting below would create a bare record for a job that does not exist
    count_plan(ctx, job_id, item, 0)  # failed before its plan: no tiles will ever run
    if tile is not None:
        store.tile_done(job_id, item, tile)  # the failed tile is done with; the others count
    view = store.get_item(job_id, item)
    if view is None or view.item.state in _DECIDED:
        return
    store.put_item(job_id, view.item.model_copy(update={"state": State.failed, "error": message}))


def complete_item(ctx: WorkerContext, job_id: str, item: int, *, maybe_repeat: bool) -> None:
    """The item has its outcome: count it, start the next item, end the job after the last."""
    store = ctx.store
    if store.state(job_id) is None:
        return
    first = store.tile_done(job_id, item, "complete")
    view = store.get_item(job_id, item)
    quality = view.item.result.quality if view is not None and view.item.result else None
    done = store.item_done(job_id, item, verdict=(quality or {}).get("verdict"),
                           failed=view is not None and view.item.state == State.failed)
    if view is None or view.state == State.cancelled:
        return
    if view.state == State.running and (first or maybe_repeat):
        start_items(ctx, job_id, view.n_items, 1)
    if done >= view.n_items and (job := store.get(job_id)) is not None:
        _end_job(ctx, job, maybe_repeat=maybe_repeat)


def fail_and_complete(ctx: WorkerContext, job_id: str, item: int, message: str, *, maybe_repeat: bool,
                      tile: str | None = None) -> None:
    """The item cannot go on: it fails with `message` and is completed (the job goes on)."""
    fail_item(ctx, job_id, item, message, tile=tile)
    complete_item(ctx, job_id, item, maybe_repeat=maybe_repeat)


# -- the watchdog's -----------------------------------------------------------------------------
def restart_job(ctx: WorkerContext, job: JobRecord) -> str:
    """Re-send what a stalled job is waiting for; returns what was done, for the log."""
    if job.state == State.queued:
        ctx.send_task(TASK_RUN_JOB, (job.id,), ignore_result=True)
        return "run_job re-sent"
    n = len(job.items)
    done = ctx.store.done_items(job.id)
    open_items = [i for i in range(ctx.store.claimed_items(job.id, n)) if i not in done]
    for i in open_items:
        if job.items[i].state in _DECIDED:
            # Its outcome is recorded but the count and the next step were lost: finish_item
            # on a decided item only completes it.
            ctx.send_task(TASK_FINISH_ITEM, ([], job.id, i), ignore_result=True)
        else:
            ctx.send_task(TASK_PLAN_ITEM, (job.id, i), ignore_result=True)
    if open_items:
        return f"items {open_items} re-sent"
    if len(done) >= n:
        complete_item(ctx, job.id, n - 1, maybe_repeat=True)  # ends the job
        return "job ended"
    start_items(ctx, job.id, n, min(ctx.settings.items_in_flight_per_job, n - len(done)))
    return "window refilled"


def fail_job(ctx: WorkerContext, job: JobRecord, reason: str) -> bool:
    """Fail the job and its undecided items with `reason`; False if it ended meanwhile."""
    store = ctx.store
    if not store.transition(job.id, State.failed, error=reason):
        return False
    current = store.get(job.id) or job
    for item in current.items:
        if item.state not in FINAL_STATES:
            store.put_item(job.id, item.model_copy(update={"state": State.failed, "error": reason}))
    final = store.get(job.id)
    try:  # as a job that ends by itself: its document, then the client is told
        if final is not None:
            _write_job_document(ctx, final)
    except Exception as exc:  # the store may be what is down; the record in Redis is the truth
        log.warning("job %s failed by the watchdog; job.json not written: %s", job.id, exc)
    if job.webhook_url:
        ctx.send_task(TASK_DELIVER_WEBHOOK, (job.id,))
    return True


# -- reasons ------------------------------------------------------------------------------------
def failure_reason(exc: BaseException, retries: int, time_limit_s: float | None = None) -> str:
    """Why a task gave up, as a client can read it: which backend, not its internal address
    (exception messages are not quoted: they may name internal hosts, buckets or keys), and how
    many retries were spent on it. `time_limit_s`: the task's soft time limit, named when that
    is what stopped it."""
    if isinstance(exc, SoftTimeLimitExceeded | TimeLimitExceeded):
        of = f" of {time_limit_s:g} s" if time_limit_s else ""
        return (f"took longer than the worker's time limit{of}: the input may be too large for "
                "one task (fewer frames, a smaller photo), or the operator can raise "
                "PRISM_TASK_TIME_LIMIT_S")
    if isinstance(exc, ConnectionError | HTTPClientError):  # refused, timed out, reset
        what = "the object store was unreachable"
    elif isinstance(exc, ClientError):
        code = exc.response.get("Error", {}).get("Code", "?")
        what = f"the object store refused a request ({code})"
    elif isinstance(exc, redis.ConnectionError | redis.TimeoutError):
        what = "the job store (Redis) was unreachable"
    else:
        what = f"internal error: {type(exc).__name__}"
    return what + (f" (gave up after {retries} retries)" if retries else "")

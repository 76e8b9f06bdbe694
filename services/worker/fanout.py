"""A job's items: the window of items in flight, item outcomes, progress units, the job's end.

Progress is counted in units: an item is 1 (plan) + its tiles + 1 (complete); until it is
planned the store assumes UNITS_PER_ITEM_ESTIMATE. The plan and complete units are counted
through the store's set of finished tiles (as "plan" and "complete"), so a task that runs
twice counts once; the "complete" entry also tells whether this is the item's first completion.

A task that may be a repeat (redelivered after a lost worker, or retried after an error part
way) refills the window even if an earlier run may have: starting one item too many is
harmless (each index is claimed once), starting one too few could stall the job forever.
"""

from __future__ import annotations

from prism_common.queue import TASK_DELIVER_WEBHOOK, TASK_PLAN_ITEM
from prism_common.records import ItemRecord, ItemResult, JobRecord, State
from prism_common.store import UNITS_PER_ITEM_ESTIMATE

from . import context
from .app import app
from .keys import job_key

__all__ = ["complete_item", "count_plan", "fail_item", "start_job", "succeed_item"]


def start_items(job_id: str, n_items: int, count: int) -> None:
    for _ in range(count):
        i = context.store().next_item(job_id)
        if i >= n_items:
            return
        app.send_task(TASK_PLAN_ITEM, (job_id, i))


def start_job(job_id: str, *, maybe_repeat: bool) -> None:
    """Move a queued job to running and start its first window of items."""
    store = context.store()
    job = store.get(job_id)
    if job is None or job.state not in (State.queued, State.running):
        return
    if not store.transition(job_id, State.running) and not maybe_repeat:
        return  # another delivery of run_job started it
    n = len(job.items)
    if n == 0:  # nothing will ever complete to end it
        _finish_job(job, maybe_repeat=maybe_repeat)
        return
    start_items(job_id, n, min(context.settings().items_in_flight_per_job, n))


def count_plan(job_id: str, item: int, tiles: int) -> None:
    """Count the plan's unit and replace the item's estimate by its real size, once."""
    store = context.store()
    if store.tile_done(job_id, item, "plan"):
        store.add_units(job_id, total=tiles + 2 - UNITS_PER_ITEM_ESTIMATE)


def succeed_item(job_id: str, record: ItemRecord, result: ItemResult, outputs: dict[str, str]) -> None:
    context.store().put_item(job_id, record.model_copy(
        update={"state": State.succeeded, "error": None, "result": result, "outputs": outputs}))


def fail_item(job_id: str, item: int, message: str, *, tile: str | None = None) -> None:
    """Record the item's failure (unless it already has an outcome) and count its units."""
    store = context.store()
    if store.state(job_id) is None:
        return  # counting below would create a bare record for a job that does not exist
    count_plan(job_id, item, 0)  # failed before its plan: no tiles will ever run
    if tile is not None:
        store.tile_done(job_id, item, tile)  # the failed tile is done with; the others count
    view = store.get_item(job_id, item)
    if view is None or view.item.state in (State.succeeded, State.failed):
        return
    store.put_item(job_id, view.item.model_copy(update={"state": State.failed, "error": message}))


def complete_item(job_id: str, item: int, *, maybe_repeat: bool) -> None:
    """The item has its outcome: count it, start the next item, end the job after the last."""
    store = context.store()
    if store.state(job_id) is None:
        return
    first = store.tile_done(job_id, item, "complete")
    done = store.item_done(job_id, item)
    view = store.get_item(job_id, item)
    if view is None or view.state == State.cancelled:
        return
    if view.state == State.running and (first or maybe_repeat):
        start_items(job_id, view.n_items, 1)
    if done >= view.n_items and (job := store.get(job_id)) is not None:
        _finish_job(job, maybe_repeat=maybe_repeat)


def _finish_job(job: JobRecord, *, maybe_repeat: bool) -> None:
    store = context.store()
    ok = any(item.state == State.succeeded for item in job.items)
    moved = store.transition(job.id, State.succeeded if ok else State.failed,
                             error=None if ok else "all items failed")
    if not (moved or maybe_repeat):
        return  # the job had already ended: whoever ended it wrote job.json
    final = store.get(job.id)
    if final is None or final.state not in (State.succeeded, State.failed):
        return  # cancelled at the last moment
    context.objects().put_bytes(job_key(job.id, "job.json"),
                                (final.model_dump_json(indent=2) + "\n").encode(), "application/json")
    if final.webhook_url:
        app.send_task(TASK_DELIVER_WEBHOOK, (job.id,))

"""What the watchdog does to a stalled job: restart it where it stopped, or fail it with a reason.

A restart re-sends the tasks that would have come next. Tasks are idempotent (deterministic keys,
exists-checks, counting by set membership), so re-sending work that did in fact happen writes
the same objects again and counts nothing twice.
"""

from __future__ import annotations

import logging

from prism_common.queue import TASK_DELIVER_WEBHOOK, TASK_FINISH_ITEM, TASK_PLAN_ITEM, TASK_RUN_JOB
from prism_common.records import FINAL_STATES, JobRecord, State

from . import context, fanout
from .app import app
from .keys import job_key

__all__ = ["fail_job", "restart_job"]

log = logging.getLogger(__name__)


def _done_items(job_id: str) -> set[int]:
    return {int(i) for i in context.redis_client().smembers(f"prism:job:{job_id}:done")}


def _claimed(job_id: str, n_items: int) -> int:
    """How many items have been started (claimed through the store's `next` counter)."""
    value = context.redis_client().get(f"prism:job:{job_id}:next")
    return min(int(value or 0), n_items)


def restart_job(job: JobRecord) -> str:
    """Re-send what the job is waiting for; returns what was done, for the log."""
    if job.state == State.queued:
        app.send_task(TASK_RUN_JOB, (job.id,), ignore_result=True)
        return "run_job re-sent"
    n = len(job.items)
    done = _done_items(job.id)
    open_items = [i for i in range(_claimed(job.id, n)) if i not in done]
    for i in open_items:
        if job.items[i].state in (State.succeeded, State.failed):
            # Its outcome is recorded but the count and the next step were lost: finish_item
            # on a decided item only completes it.
            app.send_task(TASK_FINISH_ITEM, ([], job.id, i), ignore_result=True)
        else:
            app.send_task(TASK_PLAN_ITEM, (job.id, i), ignore_result=True)
    if open_items:
        return f"items {open_items} re-sent"
    if len(done) >= n:
        fanout.complete_item(job.id, n - 1, maybe_repeat=True)  # ends the job
        return "job ended"
    fanout.start_items(job.id, n, min(context.settings().items_in_flight_per_job, n - len(done)))
    return "window refilled"


def fail_job(job: JobRecord, reason: str) -> bool:
    """Fail the job and its undecided items with `reason`; False if it ended meanwhile."""
    store = context.store()
    if not store.transition(job.id, State.failed, error=reason):
        return False
    current = store.get(job.id) or job
    for item in current.items:
        if item.state not in FINAL_STATES:
            store.put_item(job.id, item.model_copy(update={"state": State.failed, "error": reason}))
    final = store.get(job.id)
    try:  # as a job that ends by itself: its document, then the client is told
        if final is not None:
            context.objects().put_bytes(job_key(job.id, "job.json"),
                                        (final.model_dump_json(indent=2) + "\n").encode(),
                                        "application/json")
    except Exception as exc:  # the store may be what is down; the record in Redis is the truth
        log.warning("job %s failed by the watchdog; job.json not written: %s", job.id, exc)
    if job.webhook_url:
        app.send_task(TASK_DELIVER_WEBHOOK, (job.id,))
    return True

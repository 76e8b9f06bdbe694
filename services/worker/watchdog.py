"""The watchdog: no job stays queued or running forever, and what has outlived its time goes.

Every worker runs it in a thread of its main process (started by `prism_worker.app`); each
`watchdog_interval_s` the workers race for a lock in the store and the one that wins sweeps, so
one sweep runs per interval whatever the number of workers and hosts, and the sweeps go on while
any worker is alive. What a sweep learns is kept in the store (`JobStore.set_watch`), on the
context's clock (Redis's), so the next sweep may run on another host. A sweep looks at every
queued and running job:

* progress (``units_done``) moved since the last sweep: it is alive;
* a task of its own is waiting in the broker or held by a worker (broker.py): it is waiting its
  turn, however deep the queue;
* neither, for `job_stall_timeout_s`: its next step was lost (a worker's acknowledgement or a
  chord's count that died with Redis, say). It is restarted where it stopped
  (`lifecycle.restart_job`), up to `job_stall_restarts` times; if it still makes no progress it
  fails, saying so (`lifecycle.fail_job`);
* any job not final `job_max_age_s` after submission fails, whatever else (a task that kills its
  worker each time it is handed out would otherwise be redelivered for ever).

Webhooks, in the same sweep: a job's delivery is due from its ending (written with it) until it
is delivered or given up; one due for `job_stall_timeout_s` with no task of its own in the
broker was lost and is sent again (`resend_webhooks`).

Retention, in the same sweep: uploads older than `upload_ttl_s` go (the file, a video's probe
and decoded frames, what point searches found, the record), and, when the operator sets
`job_ttl_s`, ended jobs older than that (every object under jobs/{id}/, the record). Objects go
before records, so a sweep cut short leaves the thing listed and the next one finishes it;
deleting twice is harmless. An upload's expiry does not touch the outputs of the jobs that read
it.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from prism_common.queue import TASK_DELIVER_WEBHOOK
from prism_common.records import State
from prism_common.storage import object_key
from prism_common.store import WATCHDOG_LOCK_KEY
from prism_common.upload_keys import points_prefix, upload_key, video_info_key

from . import lifecycle
from .broker import pending_job_ids
from .context import WorkerContext

__all__ = ["LOCK_KEY", "Watchdog", "expire_jobs", "expire_uploads", "resend_webhooks", "sweep", "try_sweep"]

log = logging.getLogger(__name__)

LOCK_KEY = WATCHDOG_LOCK_KEY
_indexed = False  # this process listed the uploads made before they were listed for expiry


def sweep(ctx: WorkerContext, now: float) -> dict[str, int]:
    """One pass over the unfinished jobs at time `now` (s); returns counts of what was done."""
    settings, store = ctx.settings, ctx.store
    counts = {"jobs": 0, "restarted": 0, "failed": 0}
    jobs = store.unfinished()
    counts["jobs"] = len(jobs)
    pending: set[str] | None = None  # read only if some job looks stalled
    for job_id, done, created in jobs:
        watch = store.get_watch(job_id)
        if now - created > settings.job_max_age_s:
            job = store.get(job_id)
            if job is not None and lifecycle.fail_job(
                    ctx, job, f"not finished {settings.job_max_age_s} s after it was submitted"):
                counts["failed"] += 1
            continue
        if not watch or int(watch["units"]) != done:
            # Moving again: the restarts it had are forgiven (progress is finite, so a job that
            # keeps moving between stalls still ends).
            store.set_watch(job_id, since=now, units=done, restarts=0, ttl_s=settings.job_max_age_s + 3600)
            continue
        if now - float(watch["since"]) < settings.job_stall_timeout_s:
            continue
        if pending is None:
            pending = pending_job_ids(ctx.redis)
        if job_id in pending:
            store.set_watch(job_id, since=now)  # waiting its turn: the clock restarts
            continue
        job = store.get(job_id)
        if job is None or job.state not in (State.queued, State.running):
            continue
        restarts = int(watch.get("restarts", 0))
        if restarts >= settings.job_stall_restarts:
            reason = (f"stalled: no progress for {settings.job_stall_timeout_s} s, "
                      f"{restarts} restarts did not help")
            if lifecycle.fail_job(ctx, job, reason):
                counts["failed"] += 1
                log.error("watchdog: job %s failed: %s", job_id, reason)
            continue
        what = lifecycle.restart_job(ctx, job)
        store.set_watch(job_id, since=now, restarts=restarts + 1)
        counts["restarted"] += 1
        log.warning("watchdog: job %s made no progress for %s s: %s", job_id,
                    settings.job_stall_timeout_s, what)
    return counts


def try_sweep(ctx: WorkerContext, holder: str) -> dict[str, int] | None:
    """Sweep if this process wins the interval's lock; None if another holds it."""
    if not ctx.store.take_watchdog_lock(holder, ctx.settings.watchdog_interval_s):
        return None
    now = ctx.clock()
    counts = sweep(ctx, now)
    counts["webhooks resent"] = resend_webhooks(ctx, now)
    counts["uploads expired"] = expire_uploads(ctx, now)
    counts["jobs expired"] = expire_jobs(ctx, now)
    return counts


def resend_webhooks(ctx: WorkerContext, now: float) -> int:
    """Send again the deliveries due for `job_stall_timeout_s` with no task of theirs in the
    broker: lost with Redis's last second (a restart under AOF everysec), as a job's next step
    can be. A delivery that did go out but whose mark was lost goes twice, with one
    ``webhook-id``: receivers drop the repeat (Standard Webhooks)."""
    due = ctx.store.webhooks_due(now - ctx.settings.job_stall_timeout_s)
    if not due:
        return 0
    pending = pending_job_ids(ctx.redis)
    sent = 0
    for job_id in due:
        # Not queued nor waiting for a retry; and still due now (a delivery may have finished
        # between the list and the broker's scan).
        if job_id not in pending and ctx.store.webhook_resent(job_id, now):
            ctx.send_task(TASK_DELIVER_WEBHOOK, (job_id,))
            log.warning("job %s: its webhook was due with no delivery in the broker; sent", job_id)
            sent += 1
    return sent


# -- retention ----------------------------------------------------------------------------------
def expire_uploads(ctx: WorkerContext, now: float) -> int:
    """Delete the uploads older than `upload_ttl_s` at `now` (s); how many went."""
    ttl = ctx.settings.upload_ttl_s
    if ttl <= 0:
        return 0
    store, objects = ctx.store, ctx.objects
    global _indexed
    if not _indexed:  # once per process: uploads made before they were listed for expiry
        if added := store.index_old_uploads():
            log.info("listed %d older uploads for expiry", added)
        _indexed = True
    gone = 0
    for upload_id in store.uploads_before(now - ttl):
        upload = store.get_upload(upload_id)
        if upload is not None:
            tenant = upload["tenant"]
            frames = objects.list_keys(upload_key(tenant, upload_id) + ".frames/")
            found = objects.list_keys(points_prefix(tenant, upload_id))
            objects.delete_keys([upload["key"], video_info_key(tenant, upload_id), *frames, *found])
        store.delete_upload(upload_id)
        gone += 1
    if gone:
        log.info("deleted %d uploads older than %d s", gone, ttl)
    return gone


def expire_jobs(ctx: WorkerContext, now: float) -> int:
    """Delete the ended jobs submitted more than `job_ttl_s` before `now` (s)."""
    ttl = ctx.settings.job_ttl_s
    if ttl <= 0:
        return 0
    store, objects = ctx.store, ctx.objects
    gone = 0
    for job_id in store.ended_before(now - ttl):
        objects.delete_keys(objects.list_keys(object_key("jobs", job_id) + "/"))
        gone += store.delete_job(job_id)
    if gone:
        log.info("deleted %d jobs submitted more than %d s ago", gone, ttl)
    return gone


# -- the thread ---------------------------------------------------------------------------------
class Watchdog:
    """The sweeping thread of one worker's main process: `start` at worker_ready, `stop` at
    worker_shutdown (the app's wiring)."""

    def __init__(self, context: Callable[[], WorkerContext], holder: str) -> None:
        self._context, self._holder = context, holder
        self._stop = threading.Event()

    def start(self) -> None:
        threading.Thread(target=self._loop, name="prism-watchdog", daemon=True).start()

    def stop(self) -> None:
        self._stop.set()

    def _loop(self) -> None:
        ctx = self._context()
        while not self._stop.wait(ctx.settings.watchdog_interval_s):
            try:
                try_sweep(ctx, self._holder)
            except Exception as exc:  # Redis down, say: the next interval tries again
                log.warning("watchdog sweep failed: %r", exc)

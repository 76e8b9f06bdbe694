"""The watchdog: no job stays queued or running forever.

Every worker runs it in a thread of its main process; each `watchdog_interval_s` the workers
race for a Redis lock (SET NX with the interval as expiry) and the one that wins sweeps, so one
sweep runs per interval whatever the number of workers and hosts, and the sweeps go on while
any worker is alive. What a sweep learns is kept in Redis (``prism:watch:{id}``), on Redis's
clock, so the next sweep may run on another host. A sweep looks at every queued and running job:

* progress (``units_done``) moved since the last sweep: it is alive;
* a task of its own is waiting in the broker or held by a worker: it is waiting its turn, however
  deep the queue;
* neither, for `job_stall_timeout_s`: its next step was lost (a worker's acknowledgement or a
  chord's count that died with Redis, say). It is restarted where it stopped (recovery.py), up
  to `job_stall_restarts` times; if it still makes no progress it fails, saying so;
* any job not final `job_max_age_s` after submission fails, whatever else (a task that kills its
  worker each time it is handed out would otherwise be redelivered for ever).

The same sweep deletes uploads older than `upload_ttl_s`, and ended jobs older than `job_ttl_s`
when that is set (retention.py).
"""

from __future__ import annotations

import logging
import threading

import redis
from celery.signals import worker_ready, worker_shutdown
from prism_common.records import State
from prism_common.settings import Settings

from . import context, recovery, retention
from .pending import pending_job_ids

__all__ = ["LOCK_KEY", "sweep", "try_sweep"]

log = logging.getLogger(__name__)

LOCK_KEY = "prism:watchdog:lock"
_WATCH = "prism:watch:"
_stop = threading.Event()


def _jobs(client: redis.Redis) -> list[tuple[str, int, float]]:
    """(id, units_done, created at in s) of every queued and running job."""
    ids = [*client.zrange("prism:state:queued", 0, -1), *client.zrange("prism:state:running", 0, -1)]
    with client.pipeline(transaction=False) as pipe:
        for job_id in ids:
            pipe.hmget(f"prism:job:{job_id}", "units_done", "score")
        rows = pipe.execute()
    return [(job_id, int(done or 0), float(score or 0) / 1e6)
            for job_id, (done, score) in zip(ids, rows, strict=True)]


def sweep(settings: Settings, now: float) -> dict[str, int]:
    """One pass over the unfinished jobs at time `now` (s); returns counts of what was done."""
    client, store = context.redis_client(), context.store()
    counts = {"jobs": 0, "restarted": 0, "failed": 0}
    jobs = _jobs(client)
    counts["jobs"] = len(jobs)
    pending: set[str] | None = None  # read only if some job looks stalled
    for job_id, done, created in jobs:
        watch = client.hgetall(_WATCH + job_id)
        key_ttl = settings.job_max_age_s + 3600
        if now - created > settings.job_max_age_s:
            job = store.get(job_id)
            if job is not None and recovery.fail_job(
                    job, f"not finished {settings.job_max_age_s} s after it was submitted"):
                counts["failed"] += 1
            continue
        if not watch or int(watch["units"]) != done:
            # Moving again: the restarts it had are forgiven (progress is finite, so a job that
            # keeps moving between stalls still ends).
            client.hset(_WATCH + job_id, mapping={"units": done, "since": now, "restarts": 0})
            client.expire(_WATCH + job_id, key_ttl)
            continue
        if now - float(watch["since"]) < settings.job_stall_timeout_s:
            continue
        if pending is None:
            pending = pending_job_ids(client)
        if job_id in pending:
            client.hset(_WATCH + job_id, "since", now)  # waiting its turn: the clock restarts
            continue
        job = store.get(job_id)
        if job is None or job.state not in (State.queued, State.running):
            continue
        restarts = int(watch.get("restarts", 0))
        if restarts >= settings.job_stall_restarts:
            reason = (f"stalled: no progress for {settings.job_stall_timeout_s} s, "
                      f"{restarts} restarts did not help")
            if recovery.fail_job(job, reason):
                counts["failed"] += 1
                log.error("watchdog: job %s failed: %s", job_id, reason)
            continue
        what = recovery.restart_job(job)
        client.hset(_WATCH + job_id, mapping={"since": now, "restarts": restarts + 1})
        counts["restarted"] += 1
        log.warning("watchdog: job %s made no progress for %s s: %s", job_id,
                    settings.job_stall_timeout_s, what)
    return counts


def try_sweep(settings: Settings, holder: str) -> dict[str, int] | None:
    """Sweep if this process wins the interval's lock; None if another holds it."""
    client = context.redis_client()
    if not client.set(LOCK_KEY, holder, nx=True, ex=max(1, settings.watchdog_interval_s)):
        return None
    seconds, micros = client.time()
    now = seconds + micros / 1e6
    counts = sweep(settings, now)
    counts["uploads expired"] = retention.expire_uploads(settings, now)
    counts["jobs expired"] = retention.expire_jobs(settings, now)
    return counts


def _loop(holder: str) -> None:
    settings = context.settings()
    while not _stop.wait(settings.watchdog_interval_s):
        try:
            try_sweep(settings, holder)
        except Exception as exc:  # Redis down, say: the next interval tries again
            log.warning("watchdog sweep failed: %r", exc)


@worker_ready.connect
def _start(sender: object = None, **_: object) -> None:
    if context.settings().watchdog_interval_s > 0:
        holder = str(getattr(sender, "hostname", "worker"))
        threading.Thread(target=_loop, args=(holder,), name="prism-watchdog", daemon=True).start()


@worker_shutdown.connect
def _halt(**_: object) -> None:
    _stop.set()

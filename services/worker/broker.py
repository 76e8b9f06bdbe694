"""Which jobs have a task waiting in the broker or held by a worker right now: the one module
that reads kombu's internal Redis structures (kombu is pinned in pyproject.toml, and
tests/unit/worker/test_broker.py publishes real messages through Celery to check them).

kombu's Redis transport keeps waiting messages in one list per queue (prism_common.queue_lists)
and the messages workers have taken but not yet acknowledged (running, or waiting for a retry's
countdown) in the ``unacked`` hash, until they are acknowledged or handed out again. Every task
of ours takes the job id as its first argument, and Celery copies the arguments into each
message's ``argsrepr`` header in clear, so the ids are read from there without decoding bodies.
"""

from __future__ import annotations

import re

import redis
from prism_common.queue import QUEUE_SCANS, QUEUE_WEBHOOKS, queue_lists

__all__ = ["UNACKED_HASH", "pending_job_ids"]

UNACKED_HASH = "unacked"  # kombu's default `unacked_key`
_ARGSREPR = re.compile(r'"argsrepr":\s*"([^"]*)"')
_JOB_ID = re.compile(r"(?<![0-9a-f])[0-9a-f]{32}(?![0-9a-f])")
_BATCH = 500


def _ids(raw: str) -> set[str]:
    return {job_id for args in _ARGSREPR.findall(raw) for job_id in _JOB_ID.findall(args)}


def pending_job_ids(client: redis.Redis) -> set[str]:
    """Ids of the jobs that have at least one task queued, running or due for a retry."""
    found: set[str] = set()
    for queue in (QUEUE_SCANS, QUEUE_WEBHOOKS):
        for name in queue_lists(queue):
            # In slices: a deep queue is read without one reply of its whole size.
            for start in range(0, client.llen(name), _BATCH):
                for raw in client.lrange(name, start, start + _BATCH - 1):
                    found |= _ids(raw if isinstance(raw, str) else raw.decode("utf-8", "replace"))
    for _, raw in client.hscan_iter(UNACKED_HASH, count=_BATCH):
        found |= _ids(raw if isinstance(raw, str) else raw.decode("utf-8", "replace"))
    return found

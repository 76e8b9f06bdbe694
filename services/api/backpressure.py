"""Back-pressure: refuse new jobs while more work waits than the workers can be trusted to hold.

The measure is the scans queue's depth (tasks waiting, not jobs): a job is one task when
submitted and fans out later, so a deep queue means the workers are behind whatever the jobs'
sizes. Refusing with 503 + Retry-After keeps the backlog (and Redis's memory) bounded and tells
clients when to come back, instead of accepting work that would wait for hours.
"""

from __future__ import annotations

import redis
from prism_common.queue import QUEUE_SCANS, queue_depth
from prism_common.settings import Settings

from .problems import Problem

__all__ = ["check_queue_depth"]


def check_queue_depth(client: redis.Redis, settings: Settings) -> None:
    """Raise 503 with Retry-After if the scans queue is at or over `queue_max_depth`."""
    limit = settings.queue_max_depth
    if limit <= 0:
        return
    depth = queue_depth(client, QUEUE_SCANS)
    if depth >= limit:
        raise Problem(
            "at-capacity",
            f"the service is at capacity ({depth} tasks waiting, limit {limit}); no job was created",
            headers={"Retry-After": str(settings.queue_retry_after_s)})

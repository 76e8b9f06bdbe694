"""Task durations, recorded by the workers in Redis and read by the API's /metrics.

Workers are separate processes (and machines), so their histograms are summed in Redis: one
hash per task name with a count per bucket, the total count and the sum of seconds.
"""

from __future__ import annotations

from typing import cast

import redis

__all__ = ["BUCKETS_S", "read_task_durations", "record_task_duration"]

BUCKETS_S = (0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0)
_KEY = "prism:metrics:task:"


def record_task_duration(client: redis.Redis, task: str, seconds: float) -> None:
    """Add one run of `task` that took `seconds` to its histogram."""
    with client.pipeline() as pipe:
        for bound in BUCKETS_S:
            if seconds <= bound:
                pipe.hincrby(_KEY + task, f"le:{bound}", 1)
        pipe.hincrby(_KEY + task, "count", 1)
        pipe.hincrbyfloat(_KEY + task, "sum", seconds)
        pipe.sadd(_KEY + "names", task)
        pipe.execute()


def read_task_durations(client: redis.Redis) -> dict[str, dict[str, float]]:
    """{task: {"le:0.01": n, ..., "count": n, "sum": s}} for every task recorded."""
    names = sorted(cast("set[str]", client.smembers(_KEY + "names")))  # a decoding client
    with client.pipeline() as pipe:
        for name in names:
            pipe.hgetall(_KEY + name)
        rows = pipe.execute()
    return {name: {k: float(v) for k, v in row.items()} for name, row in zip(names, rows, strict=True)}

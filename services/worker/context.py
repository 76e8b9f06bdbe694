"""`WorkerContext`: everything the worker's logic talks to, built once per process and passed in.

The worker's app (`prism_worker.app`) builds one when a process starts (Celery's prefork pool
forks its children from the main process: sockets and boto3 clients made before the fork must
not be shared, so each child builds its own) and the tasks hand it to the logic. Tests build one
from in-memory fakes (tests/unit/worker/conftest.py) or from a real Redis and bucket.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import redis
from prism_common.redis_client import redis_client
from prism_common.settings import Settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

__all__ = ["Clock", "SendTask", "WorkerContext", "build_context"]


class SendTask(Protocol):
    """Send a task by name (Celery's ``app.send_task``): how the logic starts the next step."""

    def __call__(self, name: str, args: Sequence[Any] = ..., **options: Any) -> object: ...


Clock = Callable[[], float]
"""Seconds since the epoch, on the clock every worker shares (Redis's)."""


@dataclass(frozen=True, eq=False)  # hashed by identity: per-process caches key on it
class WorkerContext:
    """The worker's collaborators. Frozen: a variant for a test is made with dataclasses.replace."""

    settings: Settings
    redis: redis.Redis
    store: JobStore
    objects: ObjectStore
    link_objects: ObjectStore  # the bucket at its public endpoint: presigns clients' links
    clock: Clock
    send_task: SendTask


def build_context(settings: Settings, send_task: SendTask) -> WorkerContext:
    """The real collaborators for `settings`: Redis (with timeouts, so a stalled Redis surfaces
    as an error the task retries, not a hung worker), the job store on it, the bucket."""
    client = redis_client(settings, health_check_interval=30, socket_timeout=30, socket_connect_timeout=5)
    store = JobStore(client)
    return WorkerContext(settings=settings, redis=client, store=store,
                         objects=ObjectStore.from_settings(settings),
                         link_objects=ObjectStore.from_settings(settings, for_links=True),
                         clock=store.server_time, send_task=send_task)

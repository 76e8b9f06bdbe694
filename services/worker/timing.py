"""Task durations for /metrics: measured between Celery's task_prerun and task_postrun signals.

Both signals fire in the process that runs the task, so a dict keyed by task id carries the
start time across; the histogram itself lives in Redis (prism_common.metrics).
"""

from __future__ import annotations

import logging
import time

from celery import Task
from celery.signals import task_postrun, task_prerun
from prism_common.metrics import record_task_duration

from . import context

__all__: list[str] = []

log = logging.getLogger(__name__)
_started: dict[str, float] = {}


@task_prerun.connect
def _start(task_id: str | None = None, **_: object) -> None:
    if task_id:
        _started[task_id] = time.perf_counter()


@task_postrun.connect
def _stop(task_id: str | None = None, task: Task | None = None, **_: object) -> None:
    start = _started.pop(task_id or "", None)
    if start is None or task is None:
        return
    try:
        record_task_duration(context.redis_client(), task.name, time.perf_counter() - start)
    except Exception as exc:  # a metric must never fail the task it measures
        log.warning("task duration not recorded: %s", exc)

"""The worker's Celery app and its wiring: ``celery -A prism_worker.app worker -Q scans,frames,webhooks``.

Nothing here runs at import but the app's creation and the connection of the signals below:

* the configuration (late acks, prefetch 1, routes, the Redis broker and backend: the one the API
  sends with, `prism_common.queue.configure_celery`) is read when Celery first needs it;
* each worker process builds its `WorkerContext` when it starts (worker_process_init, in each
  prefork child: clients made before the fork must not be shared), and `worker_context()` is the
  one accessor the tasks (prism_worker.tasks) get it from;
* the main process, when the worker is ready, makes the bucket if needed and starts the
  watchdog's thread (prism_worker.watchdog), stopped at shutdown;
* task durations for /metrics are measured between task_prerun and task_postrun (both fire in
  the process that runs the task); the histogram lives in Redis (prism_common.metrics).
"""

from __future__ import annotations

import faulthandler
import logging
import os
import signal
import threading
import time
from typing import Any

import cv2
from celery import Celery, Task
from celery.signals import (
    task_postrun,
    task_prerun,
    worker_init,
    worker_process_init,
    worker_ready,
    worker_shutdown,
)
from prism_common.metrics import record_task_duration
from prism_common.queue import configure_celery
from prism_common.settings import get_settings

from .context import WorkerContext, build_context
from .watchdog import Watchdog

__all__ = ["DUMP_STACKS_SIGNAL", "app", "worker_context"]

log = logging.getLogger(__name__)

app = Celery("prism")
app.conf.include = ["prism_worker.tasks"]

DUMP_STACKS_SIGNAL = signal.SIGUSR2

_context: WorkerContext | None = None
_context_lock = threading.Lock()
_watchdog: Watchdog | None = None
_started: dict[str, float] = {}  # task id -> its start (perf_counter), for its duration


@app.on_configure.connect
def _configure(sender: Celery, **_: Any) -> None:
    configure_celery(sender, get_settings())


def _build() -> WorkerContext:
    global _context
    with _context_lock:
        _context = build_context(get_settings(), app.send_task)
        return _context


def worker_context() -> WorkerContext:
    """This process's context (built when the process started; built now in a process that was
    not started as a worker's, such as a solo pool or a test)."""
    return _context if _context is not None else _build()


def _print_stacks_on_signal() -> None:
    """`kill -USR2` on the worker's process group prints every thread's stack of every process
    into the log (fd 2: Celery replaces sys.stderr by a logging proxy with no file behind it), so
    a task that hangs can be located without a debugger. Not USR1: billiard delivers the soft
    time limit to a pool child with it."""
    faulthandler.register(DUMP_STACKS_SIGNAL, file=2, all_threads=True, chain=False)


@worker_init.connect
def _main_started(**_: Any) -> None:
    _print_stacks_on_signal()


@worker_process_init.connect
def _process_started(**_: Any) -> None:
    ctx = _build()  # the child's own clients, not the ones it inherited from the main process
    cv2.setNumThreads(ctx.settings.engine_threads)
    log.info("pool process %d: OpenCV uses %d thread(s) (PRISM_ENGINE_THREADS)", os.getpid(),
             cv2.getNumThreads())
    _print_stacks_on_signal()


@worker_ready.connect
def _worker_ready(sender: object = None, **_: Any) -> None:
    ctx = worker_context()  # the main process's (pool children build their own)
    # Outputs go to the service's bucket: make it if this is a fresh installation. A store that
    # is down now is not fatal: the tasks retry until it is back.
    try:
        ctx.objects.ensure_bucket()
    except Exception as exc:
        log.warning("could not check the bucket %r: %s", ctx.settings.s3_bucket, exc)
    if ctx.settings.watchdog_interval_s > 0:
        global _watchdog
        _watchdog = Watchdog(worker_context, str(getattr(sender, "hostname", "worker")))
        _watchdog.start()


@worker_shutdown.connect
def _worker_shutdown(**_: Any) -> None:
    if _watchdog is not None:
        _watchdog.stop()


@task_prerun.connect
def _task_started(task_id: str | None = None, **_: Any) -> None:
    if task_id:
        _started[task_id] = time.perf_counter()


@task_postrun.connect
def _task_ended(task_id: str | None = None, task: Task[Any, Any] | None = None, **_: Any) -> None:
    start = _started.pop(task_id or "", None)
    if start is None or task is None:
        return
    try:
        record_task_duration(worker_context().redis, task.name, time.perf_counter() - start)
    except Exception as exc:  # a metric must never fail the task it measures
        log.warning("task duration not recorded: %s", exc)

"""The Celery application both sides share, and the names of the worker's tasks.

The API only sends tasks by name through this app, so it never imports the worker (nor numpy
or OpenCV).
"""

from __future__ import annotations

import redis
from celery import Celery

from .broker_transport import transport_for
from .redis_client import celery_transport_options, celery_url
from .settings import Settings

__all__ = ["QUEUE_FRAMES", "QUEUE_SCANS", "QUEUE_WEBHOOKS", "TASK_EXTRACT_FRAME", "TASK_FIND_POINTS",
           "TASK_RUN_JOB", "WORKER_QUEUES", "configure_celery", "make_celery", "queue_depth", "queue_lists",
           "time_limits"]

TASK_RUN_JOB = "prism.run_job"
TASK_PLAN_ITEM = "prism.plan_item"
TASK_SCAN_TILE = "prism.scan_tile"
TASK_FINISH_ITEM = "prism.finish_item"
TASK_SCAN_FRAME = "prism.scan_frame"
TASK_SPLIT_VIDEO = "prism.split_video"  # a video's split, from the part a time-bounded one left
TASK_DELIVER_WEBHOOK = "prism.deliver_webhook"
TASK_EXTRACT_FRAME = "prism.extract_frame"
TASK_FIND_POINTS = "prism.find_points"  # an upload's box and points, for the web page
QUEUE_SCANS = "scans"
QUEUE_WEBHOOKS = "webhooks"
# A person waits on a frame to mark (or on the points found in it): its own queue, so it is not
# stuck behind a long scan queue (a worker takes from its queues in turn).
QUEUE_FRAMES = "frames"
WORKER_QUEUES = ",".join((QUEUE_SCANS, QUEUE_FRAMES, QUEUE_WEBHOOKS))
"""What a worker consumes: ``celery -A prism_worker.app worker -Q`` this."""


# kombu's Redis transport keeps a queue as the list named after it, and messages sent with a
# priority in sibling lists "<queue>\x06\x16<step>"; all of them are waiting work.
_PRIORITY_STEPS = (3, 6, 9)


def queue_lists(queue: str) -> list[str]:
    """The Redis lists holding `queue`'s waiting messages."""
    return [queue, *(f"{queue}\x06\x16{step}" for step in _PRIORITY_STEPS)]


def queue_depth(client: redis.Redis, queue: str) -> int:
    """How many tasks wait in `queue` (not counting those a worker has taken)."""
    with client.pipeline(transaction=False) as pipe:
        for name in queue_lists(queue):
            pipe.llen(name)
        return sum(pipe.execute())


# Tasks that only start others or post a webhook are short whatever the input: a tight limit.
_SHORT_TASK_S = {TASK_RUN_JOB: 60.0, TASK_DELIVER_WEBHOOK: 60.0}
_ITEM_TASKS = (TASK_PLAN_ITEM, TASK_SCAN_TILE, TASK_FINISH_ITEM, TASK_SCAN_FRAME, TASK_SPLIT_VIDEO,
               TASK_EXTRACT_FRAME, TASK_FIND_POINTS)


def time_limits(settings: Settings) -> dict[str, dict[str, float]]:
    """Soft and hard time limits (s) of every task, as Celery's task annotations.

    At the soft limit the task gets SoftTimeLimitExceeded, which fails its item with the reason
    (the task's on_failure); the hard limit, a margin later, kills a task that ignored it.
    """
    soft = {name: settings.task_time_limit_s for name in _ITEM_TASKS} | _SHORT_TASK_S
    return {name: {"soft_time_limit": s, "time_limit": s + settings.task_hard_margin_s}
            for name, s in soft.items()}


def make_celery(settings: Settings) -> Celery:
    """A Celery app on the settings' Redis, configured for at-least-once delivery."""
    app = Celery("prism")
    configure_celery(app, settings)
    return app


def configure_celery(app: Celery, settings: Settings) -> None:
    """Configure `app` as `make_celery` does (the worker's app does it when Celery first reads
    its configuration, so that importing the worker reads no settings)."""
    app.conf.update(
        broker_url=celery_url(settings),
        # kombu's Redis transport with the fix that keeps a worker alive through a Redis restart.
        broker_transport=transport_for(celery_url(settings)),
        result_backend=celery_url(settings),
        task_acks_late=True,  # a task is acked when done, so a lost worker's task is redone
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,  # one task at a time per process: fair across jobs
        task_default_queue=QUEUE_SCANS,
        task_routes={TASK_DELIVER_WEBHOOK: {"queue": QUEUE_WEBHOOKS},
                     TASK_EXTRACT_FRAME: {"queue": QUEUE_FRAMES},
                     TASK_FIND_POINTS: {"queue": QUEUE_FRAMES}},
        # Kombu looks for a lost worker's unacked messages only every 10th restore cycle by
        # default (100 s); every cycle brings them back within visibility_timeout + 10 s.
        broker_transport_options={"visibility_timeout": settings.visibility_timeout_s,
                                  "unacked_restore_throttle": 1, **celery_transport_options(settings)},
        result_backend_transport_options={"visibility_timeout": settings.visibility_timeout_s,
                                          **celery_transport_options(settings)},
        result_expires=86400,
        task_serializer="json",
        result_serializer="json",
        accept_content=["json"],
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
        task_annotations=time_limits(settings),
    )

"""The Celery application both sides share, and the names of the worker's tasks.

The API only sends tasks by name through this app, so it never imports the worker (nor numpy
or OpenCV).
"""

from __future__ import annotations

from celery import Celery

from .settings import Settings

__all__ = ["QUEUE_SCANS", "QUEUE_WEBHOOKS", "TASK_RUN_JOB", "make_celery"]

TASK_RUN_JOB = "prism.run_job"
TASK_PLAN_ITEM = "prism.plan_item"
TASK_SCAN_TILE = "prism.scan_tile"
TASK_FINISH_ITEM = "prism.finish_item"
TASK_DELIVER_WEBHOOK = "prism.deliver_webhook"
QUEUE_SCANS = "scans"
QUEUE_WEBHOOKS = "webhooks"


def make_celery(settings: Settings) -> Celery:
    """A Celery app on the settings' Redis, configured for at-least-once delivery."""
    app = Celery("prism", broker=settings.redis_url, backend=settings.redis_url)
    app.conf.update(
        task_acks_late=True,  # a task is acked when done, so a lost worker's task is redone
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,  # one task at a time per process: fair across jobs
        task_default_queue=QUEUE_SCANS,
        task_routes={TASK_DELIVER_WEBHOOK: {"queue": QUEUE_WEBHOOKS}},
        # Kombu looks for a lost worker's unacked messages only every 10th restore cycle by
        # default (100 s); every cycle brings them back within visibility_timeout + 10 s.
        broker_transport_options={"visibility_timeout": settings.visibility_timeout_s,
                                  "unacked_restore_throttle": 1},
        result_backend_transport_options={"visibility_timeout": settings.visibility_timeout_s},
        result_expires=86400,
        task_serializer="json",
        result_serializer="json",
        accept_content=["json"],
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
    )
    return app

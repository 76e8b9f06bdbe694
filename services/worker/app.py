"""The worker's Celery app: ``celery -A prism_worker.app worker -Q scans,frames,webhooks``.

The configuration (late acks, prefetch 1, routes, the Redis broker and backend) is the one
the API sends with (prism_common.queue.make_celery); the tasks are in prism_worker.tasks.
"""

from __future__ import annotations

from prism_common.queue import make_celery
from prism_common.settings import get_settings

__all__ = ["app"]

app = make_celery(get_settings())
# The watchdog's module connects its thread to the worker's start (prism_worker.watchdog).
app.conf.include = ["prism_worker.tasks", "prism_worker.watchdog"]

"""The worker's Celery app: ``celery -A prism_worker.app worker -Q scans,webhooks``.

The configuration (late acks, prefetch 1, routes, the Redis broker and backend) is the one
the API sends with (prism_common.queue.make_celery); the tasks are in prism_worker.tasks.
"""

from __future__ import annotations

from prism_common.queue import make_celery
from prism_common.settings import get_settings

__all__ = ["app"]

app = make_celery(get_settings())
app.conf.include = ["prism_worker.tasks"]
# Kombu scans for messages of lost workers (unacked past the visibility timeout) only every
# 10th restore cycle by default, i.e. every 100 s; every cycle (10 s) brings a crashed worker's
# tasks back within visibility_timeout + 10 s.
app.conf.broker_transport_options = {**app.conf.broker_transport_options,
                                     "unacked_restore_throttle": 1}

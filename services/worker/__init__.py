"""The Celery worker: ``celery -A prism_worker.app worker -Q scans,frames,webhooks``.

``app`` wires it (the Celery app, each process's `WorkerContext`, signals); ``tasks`` are thin
Celery adapters over the logic: ``lifecycle`` (every job and item transition), ``steps`` (plan,
tile, finish, or an item whole), ``video`` (split, frames, an upload's frames), ``inputs``
(references, fetch, egress), ``artifacts`` (keys, plan.json, tiles, outputs, caches),
``webhooks``, ``watchdog`` (stalls, retention) and ``broker`` (kombu's Redis structures).
"""

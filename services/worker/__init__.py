"""The Celery worker: ``celery -A prism_worker.app worker -Q scans,frames,webhooks``.

Tasks (``tasks.py``) are thin; the work is in the modules named for it: ``inputs`` and ``fetch``
read the photos, ``planning``/``scanning`` run the engine's stages, ``plans`` and ``tiles``
serialise what passes between tasks, ``outputs`` writes the results, ``fanout`` runs a job's
items, ``webhooks`` tells the client.
"""

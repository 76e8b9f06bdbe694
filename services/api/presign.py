"""Presigned download URLs, remembered for a short while.

botocore takes about a third of a millisecond per URL, and a finished 5000-item job has 15000 of
them, asked for again at every poll. A URL is reused only within a small part of its lifetime,
so every URL handed out is still valid for at least 90% of `presign_ttl_s`.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict

from prism_common.storage import ObjectStore

__all__ = ["Presigner"]


class Presigner:
    def __init__(self, objects: ObjectStore, ttl_s: int, max_entries: int = 100_000) -> None:
        self._objects, self.ttl_s, self._max = objects, ttl_s, max_entries
        self._reuse_s = min(60.0, ttl_s / 10)
        self._urls: OrderedDict[tuple[str, str], tuple[str, float]] = OrderedDict()
        self._lock = threading.Lock()

    def url(self, key: str, filename: str) -> str:
        now = time.monotonic()
        with self._lock:
            hit = self._urls.get((key, filename))
            if hit is not None and hit[1] > now:
                self._urls.move_to_end((key, filename))
                return hit[0]
        url = self._objects.presign_get(key, self.ttl_s, filename=filename)  # outside the lock
        with self._lock:
            self._urls[(key, filename)] = (url, now + self._reuse_s)
            self._urls.move_to_end((key, filename))
            while len(self._urls) > self._max:
                self._urls.popitem(last=False)
        return url

"""Per-process caches of decoded photos and plans, keyed by object key.

The tiles of one item usually land on the same few processes, and decoding the photo again for
every band would cost more than scanning it. Objects under a job's prefix never change once
written (deterministic content at deterministic keys), so a cached copy cannot go stale.
Entries are few: a decoded 50 Mpx photo is 150 MB.
"""

from __future__ import annotations

from collections import OrderedDict
from functools import lru_cache

import numpy as np

from prismcore import ScanPlan
from prismcore.images import load_image

from . import context, plans

__all__ = ["image", "plan"]

_IMAGES = 2
_images: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()


def image(key: str, max_pixels: int, label: str = "") -> np.ndarray:
    """The decoded RGB photo at `key` (shared: callers must not modify it).

    Raises InputError (quoting `label`, e.g. the uploaded file's name) for a file that is not
    a readable photo; errors are not cached.
    """
    if (key, max_pixels) in _images:
        _images.move_to_end((key, max_pixels))
        return _images[key, max_pixels]
    decoded = load_image(context.objects().get_bytes(key), max_pixels=max_pixels, name=label or key)
    decoded.flags.writeable = False  # a cached array is shared by every task of the process
    _images[key, max_pixels] = decoded
    while len(_images) > _IMAGES:
        _images.popitem(last=False)
    return decoded


@lru_cache(maxsize=8)
def _plan(key: str) -> tuple[ScanPlan, dict]:
    return plans.loads(context.objects().get_bytes(key))


def plan(key: str) -> tuple[ScanPlan, dict]:
    """The plan at `key` and what was stored beside it (shared: callers must not modify it)."""
    return _plan(key)

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

from prismcore import ScanPlan, ScanSpec
from prismcore.exif import EXIF_HEAD_BYTES, exif_focal
from prismcore.images import load_image
from prismcore.pipeline import prepare_images

from . import context, plans

__all__ = ["exif_focal_px", "image", "plan", "prepared"]

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




def exif_focal_px(key: str, image_shape: tuple[int, ...]) -> float | None:
    """The focal length (px of the decoded photo) the photo at `key` carries in its EXIF."""
    found = exif_focal(context.objects().get_head(key, EXIF_HEAD_BYTES), image_shape[1], image_shape[0])
    return found.focal_px if found else None


_prepared: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()


def prepared(key: str, max_pixels: int, spec: ScanSpec) -> np.ndarray:
    """The photo at `key` as the plan's coordinates refer to it (the engine's
    prepare_images: without lens distortion when the spec's camera has some), cached too."""
    decoded = image(key, max_pixels)
    if spec.camera is None or not spec.camera.has_distortion:
        return decoded
    if (key, max_pixels) not in _prepared:
        undistorted = prepare_images(spec, [decoded])[0]
        undistorted.flags.writeable = False
        _prepared[key, max_pixels] = undistorted
        while len(_prepared) > _IMAGES:
            _prepared.popitem(last=False)
    return _prepared[key, max_pixels]


@lru_cache(maxsize=8)
def _plan(key: str) -> tuple[ScanPlan, dict]:
    return plans.loads(context.objects().get_bytes(key))


def plan(key: str) -> tuple[ScanPlan, dict]:
    """The plan at `key` and what was stored beside it (shared: callers must not modify it)."""
    return _plan(key)

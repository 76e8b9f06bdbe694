"""Scan one tile, and merge an item's tiles into its cloud (the engine's scan_band and finish).

Both read only the job's prefix: the photos copied in by the plan step, plan.json, the tiles.
"""

from __future__ import annotations

import numpy as np
from botocore.exceptions import ClientError
from prism_common.records import ItemResult
from prism_common.storage import is_missing

from prismcore import ScanPlan, finish_scan
from prismcore.scan import merge_bands, scan_band

from . import cache, context, plans, tiles
from .keys import item_key, tile_key
from .outputs import write_outputs
from .planning import max_pixels

__all__ = ["TilesMissingError", "finish_item", "scan_tile"]


class TilesMissingError(Exception):
    """The finish step ran before every tile was stored (a chord fired early); try again later."""


def _image(job_id: str, item: int, plan: ScanPlan, index: int) -> np.ndarray:
    """Photo `index` as decoded (FacePlan.image numbering): 0 front, 1 side."""
    name = ("front", "side")[index]
    return cache.image(item_key(job_id, item, name), max_pixels(plan.spec.max_pixels))


def _scanned_image(job_id: str, item: int, plan: ScanPlan, index: int) -> np.ndarray:
    """Photo `index` as the plan's coordinates refer to it: without its lens distortion when
    the spec's camera has some (the engine's prepare_images)."""
    return cache.prepared(item_key(job_id, item, ("front", "side")[index]),
                          max_pixels(plan.spec.max_pixels), plan.spec)


def scan_tile(job_id: str, item: int, face_name: str, r0: int, r1: int) -> str:
    """Scan rows [r0, r1) of one face and store the masks, unless stored already; the key."""
    key = tile_key(job_id, item, face_name, r0, r1)
    objects = context.objects()
    if not objects.exists(key):
        plan, _ = cache.plan(item_key(job_id, item, "plan.json"))
        faces = {f.name: f for f in plan.faces}
        if face_name not in faces:
            raise ValueError(f"the plan has no face {face_name!r}")
        face = faces[face_name]
        masks = scan_band(_scanned_image(job_id, item, plan, face.image), face, r0, r1)
        objects.put_bytes(key, tiles.pack(*masks))
    return key


def _tile_bytes(objects, key: str, item: int) -> bytes:
    """A stored tile; TilesMissingError (retried) if it is not there yet."""
    try:
        return objects.get_bytes(key)
    except ClientError as exc:
        if is_missing(exc):
            raise TilesMissingError(f"tile {key.rsplit('/', 1)[-1]} of item {item} not stored yet") from None
        raise


def finish_item(job_id: str, item: int) -> tuple[ItemResult, dict[str, str]]:
    """Merge the tiles per face in row order, assemble the cloud, write the outputs.

    Raises TilesMissingError if a tile is not stored yet.
    """
    objects = context.objects()
    # Not the cached plan: finish_scan adds its timings to the plan it is given.
    plan, extra = plans.loads(objects.get_bytes(item_key(job_id, item, "plan.json")))
    scans = []
    for face in plan.faces:
        bands = sorted((r0, r1) for name, r0, r1 in extra["tiles"] if name == face.name)
        keys = [tile_key(job_id, item, face.name, r0, r1) for r0, r1 in bands]
        scans.append(merge_bands(face, [tiles.unpack(_tile_bytes(objects, k, item)) for k in keys]))
    indices = range(2 if plan.spec.two_photo else 1)
    result = finish_scan(plan, [_scanned_image(job_id, item, plan, i) for i in indices], scans)
    return write_outputs(job_id, item, plan.spec, result, [_image(job_id, item, plan, i) for i in indices])

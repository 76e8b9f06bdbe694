"""The engine's stages as the worker runs them on one item of a photo job.

A tiled item: `plan_item` (copy the photos into the job's prefix, decode them, the engine's
plan_scan, store plan.json), a `scan_tile` per face band (the engine's scan_band, masks stored),
then `finish_item` (merge the tiles, the engine's finish_scan, write the outputs). plan.json
holds the list of tiles the chord is made of, so the finish merges exactly the tiles that were
scanned, even if PRISM_TILES_PER_FACE changed in between; tiles and finish read only the job's
prefix.

An item whose points are "auto" has them found in its photo first (`prismcore.locate.search`, in
`_located`): the search's refusal fails the item with its reason, and what it found is kept
(beside the plan in plan.json for a tiled item) for report.json and the item's result.

An item of a batch is scanned whole in one task (`scan_whole_item`): a batch already has its
parallelism from the items it keeps in flight, and split into tiles each of its items would also
pay for plan.json, an object per tile, the photo decoded again and several store round trips,
which together cost more than the scan itself (see `tiles_per_face`). Its inputs are read where
their references point and nothing is stored on the way.

Each step is idempotent: the engine is deterministic and keys are too, so a re-run writes the
same objects under the same keys.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from botocore.exceptions import ClientError
from prism_common.records import ItemResult, ItemView
from prism_common.storage import ObjectStore, is_missing

from prismcore import ScanPlan, ScanSpec, finish_scan, plan_scan
from prismcore.io import exif_focal, load_image
from prismcore.locate import found_box_guard, record_found, resolve_points, scan_found
from prismcore.scan import merge_bands, scan_band

from .artifacts import (
    Tile,
    cached_image,
    cached_plan,
    cached_prepared,
    dumps_plan,
    exif_focal_px,
    item_key,
    loads_plan,
    pack_tile,
    plan_tiles,
    tile_key,
    unpack_tile,
    write_outputs,
)
from .context import WorkerContext
from .inputs import copy_input, read_input

__all__ = ["TilesMissingError", "finish_item", "max_pixels", "plan_item", "scan_tile", "scan_whole_item",
           "tiles_per_face"]


class TilesMissingError(Exception):
    """The finish step ran before every tile was stored (a chord fired early); try again later."""


def max_pixels(ctx: WorkerContext, spec_limit: int) -> int:
    """The stricter of the item's own limit and the service's."""
    return min(spec_limit, ctx.settings.max_pixels)


def tiles_per_face(ctx: WorkerContext, n_items: int) -> int:
    """Tiles give a lone photo parallelism; a batch already has it from its items in flight,
    and there each extra tile task costs more (store round trips) than its scan saves. So a job
    keeps about `tiles_per_face` tile tasks per face in flight, whatever its size."""
    in_flight = max(1, min(n_items, ctx.settings.items_in_flight_per_job))
    return max(1, -(-ctx.settings.tiles_per_face // in_flight))


# -- a tiled item -------------------------------------------------------------------------------
def plan_item(ctx: WorkerContext, view: ItemView) -> list[Tile]:
    """Plan the item (unless plan.json exists already) and return its tiles.

    Raises
    ------
    InputError
        A photo that is not readable, or points the engine refuses.
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    key = item_key(view.job_id, view.item.index, "plan.json")
    if ctx.objects.exists(key):  # a re-run: the plan is deterministic, keep the one stored
        return [(str(t[0]), int(t[1]), int(t[2])) for t in cached_plan(ctx, key)[1]["tiles"]]
    spec = view.item.spec
    limit = max_pixels(ctx, spec.max_pixels)
    front_key, front_label = copy_input(ctx, view, "front")
    front = cached_image(ctx, front_key, limit, front_label)
    side = None
    if spec.two_photo:
        side_key, side_label = copy_input(ctx, view, "side")
        side = cached_image(ctx, side_key, limit, side_label)
    spec, found = _located(spec, front)
    # The photo's own EXIF may give the focal length (a second read of its head is cheaper
    # than keeping the bytes beside the decoded cache).
    with found_box_guard(found is not None):
        plan = plan_scan(spec, front, side, exif_focal_px=exif_focal_px(ctx, front_key, front.shape))
    tiles = plan_tiles(plan, tiles_per_face(ctx, view.n_items))
    ctx.objects.put_bytes(key, dumps_plan(plan, tiles=tiles, auto_points=found), "application/json")
    return tiles


def _located(spec: ScanSpec, front: np.ndarray) -> tuple[ScanSpec, dict[str, Any] | None]:
    """The spec to measure: with points "auto", the points found in `front` filled in, and
    what the search found (`Found.report()`); else the spec as it is and None.

    Raises InputError with the search's reason when it refuses.
    """
    if spec.auto_points is None:
        return spec, None
    spec, found = resolve_points(spec, front)
    return spec, found.report()


def _image(ctx: WorkerContext, job_id: str, item: int, plan: ScanPlan, index: int) -> np.ndarray:
    """Photo `index` as decoded (FacePlan.image numbering): 0 front, 1 side."""
    name = ("front", "side")[index]
    return cached_image(ctx, item_key(job_id, item, name), max_pixels(ctx, plan.spec.max_pixels))


def _scanned_image(ctx: WorkerContext, job_id: str, item: int, plan: ScanPlan, index: int) -> np.ndarray:
    """Photo `index` as the plan's coordinates refer to it: without its lens distortion when
    the spec's camera has some (the engine's prepare_images)."""
    return cached_prepared(ctx, item_key(job_id, item, ("front", "side")[index]),
                           max_pixels(ctx, plan.spec.max_pixels), plan.spec)


def scan_tile(ctx: WorkerContext, job_id: str, item: int, face_name: str, r0: int, r1: int) -> str:
    """Scan rows [r0, r1) of one face and store the masks, unless stored already; the key."""
    key = tile_key(job_id, item, face_name, r0, r1)
    if not ctx.objects.exists(key):
        plan, _ = cached_plan(ctx, item_key(job_id, item, "plan.json"))
        faces = {f.name: f for f in plan.faces}
        if face_name not in faces:
            raise ValueError(f"the plan has no face {face_name!r}")
        face = faces[face_name]
        masks = scan_band(_scanned_image(ctx, job_id, item, plan, face.image), face, r0, r1)
        ctx.objects.put_bytes(key, pack_tile(*masks))
    return key


def _tile_bytes(objects: ObjectStore, key: str, item: int) -> bytes:
    """A stored tile; TilesMissingError (retried) if it is not there yet."""
    try:
        return objects.get_bytes(key)
    except ClientError as exc:
        if is_missing(exc):
            raise TilesMissingError(f"tile {key.rsplit('/', 1)[-1]} of item {item} not stored yet") from None
        raise


def finish_item(ctx: WorkerContext, job_id: str, item: int) -> tuple[ItemResult, dict[str, str]]:
    """Merge the tiles per face in row order, assemble the cloud, write the outputs.

    Raises TilesMissingError if a tile is not stored yet.
    """
    # Not the cached plan: finish_scan adds its timings to the plan it is given.
    plan, extra = loads_plan(ctx.objects.get_bytes(item_key(job_id, item, "plan.json")))
    scans = []
    for face in plan.faces:
        bands = sorted((r0, r1) for name, r0, r1 in extra["tiles"] if name == face.name)
        keys = [tile_key(job_id, item, face.name, r0, r1) for r0, r1 in bands]
        scans.append(merge_bands(face, [unpack_tile(_tile_bytes(ctx.objects, k, item)) for k in keys]))
    indices = range(2 if plan.spec.two_photo else 1)
    result = finish_scan(plan, [_scanned_image(ctx, job_id, item, plan, i) for i in indices], scans)
    if extra.get("auto_points") is not None:
        record_found(result.report, extra["auto_points"])
    return write_outputs(ctx, job_id, item, plan.spec, result,
                         [_image(ctx, job_id, item, plan, i) for i in indices])


# -- a batch item, whole ------------------------------------------------------------------------
def scan_whole_item(ctx: WorkerContext, view: ItemView) -> tuple[ItemResult, dict[str, str]]:
    """Measure the item and store its outputs; its result and the outputs' object keys.

    Raises
    ------
    InputError
        A photo that is not readable, points the engine refuses, a cloud over max_points.
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    spec = view.item.spec
    limit = max_pixels(ctx, spec.max_pixels)
    data, label = read_input(ctx, view, "front")
    front = load_image(data, max_pixels=limit, name=label)
    found = exif_focal(data, front.shape[1], front.shape[0])
    side = None
    if spec.two_photo:
        data, label = read_input(ctx, view, "side")
        side = load_image(data, max_pixels=limit, name=label)
    del data
    spec, auto = _located(spec, front)
    result = scan_found(spec, auto, front, side, exif_focal_px=found.focal_px if found else None)
    return write_outputs(ctx, view.job_id, view.item.index, spec, result,
                         [front] + ([side] if side is not None else []))

"""Plan one item: copy its photos in, decode them, run the engine's plan_scan, store plan.json.

plan.json holds the plan and the list of tiles the chord is made of, so the finish step merges
exactly the tiles that were scanned, even if PRISM_TILES_PER_FACE changed in between.
"""

from __future__ import annotations

from prism_common.records import ItemView

from prismcore import plan_scan

from . import cache, context, plans
from .inputs import copy_input
from .keys import item_key
from .tiles import Tile, plan_tiles

__all__ = ["max_pixels", "plan_item"]


def max_pixels(spec_limit: int) -> int:
    """The stricter of the item's own limit and the service's."""
    return min(spec_limit, context.settings().max_pixels)


def plan_item(view: ItemView) -> list[Tile]:
    """Plan the item (unless plan.json exists already) and return its tiles.

    Raises
    ------
    InputError
        A photo that is not readable, or points the engine refuses.
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    objects = context.objects()
    key = item_key(view.job_id, view.item.index, "plan.json")
    if objects.exists(key):  # a re-run: the plan is deterministic, keep the one stored
        return [tuple(t) for t in cache.plan(key)[1]["tiles"]]  # type: ignore[misc]
    spec = view.item.spec
    limit = max_pixels(spec.max_pixels)
    front_key, front_label = copy_input(view, "front")
    front = cache.image(front_key, limit, front_label)
    side = None
    if spec.two_photo:
        side_key, side_label = copy_input(view, "side")
        side = cache.image(side_key, limit, side_label)
    # The photo's own EXIF may give the focal length (a second read of its head is cheaper
    # than keeping the bytes beside the decoded cache).
    plan = plan_scan(spec, front, side, exif_focal_px=cache.exif_focal_px(front_key, front.shape))
    tiles = plan_tiles(plan, tiles_per_face(view.n_items))
    objects.put_bytes(key, plans.dumps(plan, tiles=tiles), "application/json")
    return tiles


def tiles_per_face(n_items: int) -> int:
    """Tiles give a lone photo parallelism; a batch already has it from its items in flight,
    and there each extra tile task costs more (store round trips) than its scan saves. So a job
    keeps about `tiles_per_face` tile tasks per face in flight, whatever its size."""
    settings = context.settings()
    in_flight = max(1, min(n_items, settings.items_in_flight_per_job))
    return max(1, -(-settings.tiles_per_face // in_flight))

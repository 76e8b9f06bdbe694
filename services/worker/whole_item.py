"""Scan one item whole, in one task: read its photos, plan, scan every face, write the outputs.

A batch already has its parallelism from the items it keeps in flight; split into a chord of
tile tasks, each of its items would also pay for plan.json, an object per tile, the photo
decoded again and several store round trips, which together cost more than the scan itself.
So the plan task runs such an item whole (see `planning.tiles_per_face`).

Idempotent: the inputs are read where their references point and nothing is stored on the way,
and the engine is deterministic, so a re-run writes the same outputs under the same keys.
"""

from __future__ import annotations

from prism_common.records import ItemResult, ItemView

from prismcore import run_scan
from prismcore.exif import exif_focal
from prismcore.images import load_image

from .inputs import read_input
from .outputs import write_outputs
from .planning import max_pixels

__all__ = ["scan_whole_item"]


def scan_whole_item(view: ItemView) -> tuple[ItemResult, dict[str, str]]:
    """Measure the item and store its outputs; its result and the outputs' object keys.

    Raises
    ------
    InputError
        A photo that is not readable, points the engine refuses, a cloud over max_points.
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    spec = view.item.spec
    limit = max_pixels(spec.max_pixels)
    data, label = read_input(view, "front")
    front = load_image(data, max_pixels=limit, name=label)
    found = exif_focal(data, front.shape[1], front.shape[0])
    side = None
    if spec.two_photo:
        data, label = read_input(view, "side")
        side = load_image(data, max_pixels=limit, name=label)
    del data
    result = run_scan(spec, front, side, exif_focal_px=found.focal_px if found else None)
    return write_outputs(view.job_id, view.item.index, spec, result,
                         [front] + ([side] if side is not None else []))

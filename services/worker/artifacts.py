"""What a job leaves in the bucket, and how it is (de)serialised: the object keys, plan.json, a
tile's masks, an item's outputs, and the per-process caches of decoded photos and plans.

Keys are deterministic, so a task that runs twice rewrites, never adds. ``jobs/{job}/job.json``
the final job document; under ``jobs/{job}/items/{i}/``: ``front`` and ``side`` (the inputs,
copied), ``plan.json``, ``tiles/{face}-{r0}-{r1}.npz``, ``cloud.csv``, ``cloud.ply``,
``preview.ply``, ``overlay.jpg``, ``report.json`` (and ``cloud.las``, ``cloud.laz``, ``box.glb``,
``part.step`` with ``part.step.json``, ``drawing.svg``, ``drawing.pdf``, ``drawing.dxf`` when
asked). Items of a batch, scanned whole, have only their outputs. A video item has
``frames.json`` (the frames selected), ``summary.json`` and per frame ``frame_000123/`` with
``frame.png`` (the decoded frame) and the frame's outputs. Jobs from before the overlay was a
JPEG have ``overlay.png`` instead (the API serves either).

plan.json: the round trip is exact (floats as their shortest repr, arrays keep their dtype), so
tiles scanned from a reloaded plan are the very tiles the engine would scan from the original.
A tile is its two boolean masks, one bit per pixel (np.packbits along rows), in a small .npz.

Outputs: the formats the spec asks for (the cloud as CSV, PLY, LAS or LAZ; the textured box
as glb), its display preview (``preview.ply``, at most ``prismcore.scan.cloud.PREVIEW_POINTS``
points, by an even stride: a 20-million-point cloud would not fit a browser, and
`prismcore.scan.spacing.thin_to_count`, stripe-free, costs more than the scan itself), the overlay
picture of the fit (a JPEG of at most OVERLAY_MAX_SIDE px: ~2 ms to encode where PNG took ~16 ms)
and report.json. Each file is written to a
spooled temporary file (in memory while small, on disk beyond), then streamed to the object
store, so a large cloud does not sit in memory twice.

Caches: the tiles of one item usually land on the same few processes, and decoding the photo
again for every band would cost more than scanning it. Objects under a job's prefix never change
once written, so a cached copy cannot go stale. Entries are few: a decoded 50 Mpx photo is 150 MB.
"""

from __future__ import annotations

import io
import json
import tempfile
from collections import OrderedDict
from collections.abc import Callable
from functools import lru_cache, partial
from typing import Any

import numpy as np
from prism_common.records import ItemResult
from prism_common.report_result import item_result
from prism_common.storage import object_key

from prismcore import ScanPlan, ScanResult, ScanSpec
from prismcore.geometry import EdgeFit
from prismcore.io import EXIF_HEAD_BYTES, exif_focal, load_image
from prismcore.outputs import DEFAULT_OVERLAY_FORMAT, Writer, write_part_files
from prismcore.outputs import write_outputs as write_scan_outputs
from prismcore.scan import Dimensions, FacePlan, prepare_images, row_tiles
from prismcore.spec import frame_folder

from .context import WorkerContext

__all__ = ["StoreSink", "Tile", "cached_image", "cached_plan", "cached_prepared",
           "dumps_plan", "exif_focal_px", "frame_key", "item_key", "item_result", "job_key", "loads_plan",
           "pack_tile", "plan_from_json", "plan_tiles", "plan_to_json", "put_part_files", "tile_id",
           "tile_key", "unpack_tile", "write_outputs"]


# -- keys ---------------------------------------------------------------------------------------
def job_key(job_id: str, name: str) -> str:
    return object_key("jobs", job_id, name)


def item_key(job_id: str, item: int, name: str) -> str:
    return object_key("jobs", job_id, "items", item, name)


def tile_id(face: str, r0: int, r1: int) -> str:
    """The tile's name, in object keys and in the store's set of finished tiles."""
    return f"{face}-{r0}-{r1}"


def tile_key(job_id: str, item: int, face: str, r0: int, r1: int) -> str:
    return object_key("jobs", job_id, "items", item, "tiles", f"{tile_id(face, r0, r1)}.npz")


def frame_key(job_id: str, item: int, frame: int, name: str) -> str:
    return object_key("jobs", job_id, "items", item, frame_folder(frame), name)


# -- plan.json ----------------------------------------------------------------------------------
def _array(a: np.ndarray) -> dict[str, Any]:
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.ravel().tolist()}


def _unarray(d: dict[str, Any]) -> np.ndarray:
    return np.array(d["data"], dtype=np.dtype(d["dtype"])).reshape(d["shape"])


def _face(f: FacePlan) -> dict[str, Any]:
    return {"name": f.name, "image": f.image, "region": _array(np.asarray(f.region)),
            "marked": _array(np.asarray(f.marked)), "window": [int(w) for w in f.window],
            "method": f.method, "seed": None if f.seed is None else [float(c) for c in f.seed],
            "tolerance": float(f.tolerance)}


def _unface(d: dict[str, Any]) -> FacePlan:
    seed = None if d["seed"] is None else tuple(d["seed"])
    return FacePlan(d["name"], d["image"], _unarray(d["region"]), _unarray(d["marked"]),
                    tuple(d["window"]), d["method"], seed, d["tolerance"])


def _edge(e: EdgeFit) -> dict[str, Any]:
    return {"line": _array(np.asarray(e.line)), "support": float(e.support),
            "rms_px": float(e.rms_px), "fitted": bool(e.fitted)}


def plan_to_json(plan: ScanPlan) -> dict[str, Any]:
    d = plan.dimensions
    return {
        "spec": plan.spec.model_dump(mode="json"),
        "faces": [_face(f) for f in plan.faces],
        "dimensions": {"width": float(d.width), "height": float(d.height), "depth": float(d.depth),
                       "unit": d.unit, "perspective": bool(d.perspective), "notes": list(d.notes),
                       "uncertainty": None if d.uncertainty is None else [float(u) for u in d.uncertainty]},
        "edges": {name: [_edge(e) for e in fits] for name, fits in plan.edges.items()},
        "image_sizes": [[int(w), int(h)] for w, h in plan.image_sizes],
        "warnings": list(plan.warnings),
        "timings_ms": {k: float(v) for k, v in plan.timings_ms.items()},
        "camera": plan.camera,  # JSON-ready already
        "fit": plan.fit,
    }


def plan_from_json(doc: dict[str, Any]) -> ScanPlan:
    d = doc["dimensions"]
    front, side = (_unface(f) for f in doc["faces"])
    return ScanPlan(
        spec=ScanSpec.model_validate(doc["spec"]),
        faces=(front, side),
        dimensions=Dimensions(d["width"], d["height"], d["depth"], d["unit"], d["perspective"],
                              tuple(d["notes"]),
                              None if d.get("uncertainty") is None else tuple(d["uncertainty"])),
        edges={name: [EdgeFit(_unarray(e["line"]), e["support"], e["rms_px"], e["fitted"])
                      for e in fits] for name, fits in doc["edges"].items()},
        image_sizes=[(w, h) for w, h in doc["image_sizes"]],
        warnings=list(doc["warnings"]),
        timings_ms=dict(doc["timings_ms"]),
        camera=dict(doc.get("camera") or {}),
        fit=dict(doc.get("fit") or {}),
    )


def dumps_plan(plan: ScanPlan, **extra: Any) -> bytes:
    """plan.json's bytes: the plan, plus whatever the worker keeps beside it (e.g. the tiles)."""
    return json.dumps({"plan": plan_to_json(plan), **extra}).encode()


def loads_plan(data: bytes) -> tuple[ScanPlan, dict[str, Any]]:
    doc = json.loads(data)
    return plan_from_json(doc.pop("plan")), doc


# -- tiles --------------------------------------------------------------------------------------
Tile = tuple[str, int, int]  # (face name, r0, r1): rows [r0, r1) of the face's window


def plan_tiles(plan: ScanPlan, per_face: int) -> list[Tile]:
    """Every band of every face, faces in plan order and bands in row order."""
    return [(face.name, r0, r1) for face in plan.faces for r0, r1 in row_tiles(face, per_face)]


def pack_tile(object_mask: np.ndarray, marked_mask: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, object=np.packbits(object_mask, axis=1),
                        marked=np.packbits(marked_mask, axis=1),
                        shape=np.array(object_mask.shape, dtype=np.int64))
    return buf.getvalue()


def unpack_tile(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        rows, cols = (int(n) for n in npz["shape"])
        masks = tuple(np.unpackbits(npz[name], axis=1, count=cols).astype(bool).reshape(rows, cols)
                      for name in ("object", "marked"))
    return masks[0], masks[1]


# -- outputs ------------------------------------------------------------------------------------
_SPOOL_BYTES = 64 * 2**20
# The stored overlay is a picture to look at, not a measurement: in the CLI's default format
# (a JPEG) of at most this many pixels along its longer side (a 1280x1024 photo's full-size PNG
# is 1.4 MB, more than a compact LAZ cloud).
OVERLAY_MAX_SIDE = 800
OVERLAY_FORMAT = DEFAULT_OVERLAY_FORMAT


class StoreSink:
    """A `prismcore.outputs.sink.Sink` into the object store: each file under `key(name)`.

    A file given by its writer is written to a spooled temporary file (in memory while small,
    on disk beyond), then streamed, so a large cloud does not sit in memory twice."""

    def __init__(self, ctx: WorkerContext, key: Callable[[str], str]) -> None:
        self._objects = ctx.objects
        self._key = key

    def put(self, name: str, data: bytes | Writer, media_type: str) -> None:
        if isinstance(data, bytes):
            self._objects.put_bytes(self._key(name), data, media_type)
            return
        with tempfile.SpooledTemporaryFile(max_size=_SPOOL_BYTES) as spool:
            data(spool)  # type: ignore[arg-type]
            spool.seek(0)
            self._objects.put_stream(self._key(name), spool, media_type)  # type: ignore[arg-type]


def write_outputs(ctx: WorkerContext, job_id: str, item: int, spec: ScanSpec, result: ScanResult,
                  images: list[np.ndarray], *, frame: int | None = None) -> tuple[ItemResult, dict[str, str]]:
    """Write the formats the spec asks for, the preview, the overlay of the fit on each photo
    (`images`: the front photo, and the side photo in two-photo mode, as decoded), then
    report.json (the engine's `write_outputs`); returns the item's result and the object key of
    each file written ({"csv": key, "ply": key, "preview": key, "overlay": key, "report": key});
    for a video's `frame`, under that frame's folder."""
    def key(name: str) -> str:
        return item_key(job_id, item, name) if frame is None else frame_key(job_id, item, frame, name)

    names = write_scan_outputs(result, StoreSink(ctx, key), spec=spec, images=images, preview=True,
                               overlay_format=OVERLAY_FORMAT, overlay_max_side=OVERLAY_MAX_SIDE)
    return item_result(result.report), {kind: key(name) for kind, name in names.items()}


def put_part_files(ctx: WorkerContext, job_id: str, item: int, formats: list[str],
                   measured: dict[str, Any]) -> dict[str, str]:
    """Store the part's files of `formats` (step, drawing) written from `measured` (a joint fit's
    report with its quality and scale: it makes no cloud); returns {kind: key}."""
    names = write_part_files(measured, formats, StoreSink(ctx, partial(item_key, job_id, item)))
    return {kind: item_key(job_id, item, name) for kind, name in names.items()}


# -- per-process caches ------------------------------------------------------------------------
_IMAGES = 2
_images: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()


def cached_image(ctx: WorkerContext, key: str, max_pixels: int, label: str = "") -> np.ndarray:
    """The decoded RGB photo at `key` (shared: callers must not modify it).

    Raises InputError (quoting `label`, e.g. the uploaded file's name) for a file that is not
    a readable photo; errors are not cached.
    """
    if (key, max_pixels) in _images:
        _images.move_to_end((key, max_pixels))
        return _images[key, max_pixels]
    decoded = load_image(ctx.objects.get_bytes(key), max_pixels=max_pixels, name=label or key)
    decoded.flags.writeable = False  # a cached array is shared by every task of the process
    _images[key, max_pixels] = decoded
    while len(_images) > _IMAGES:
        _images.popitem(last=False)
    return decoded


def exif_focal_px(ctx: WorkerContext, key: str, image_shape: tuple[int, ...]) -> float | None:
    """The focal length (px of the decoded photo) the photo at `key` carries in its EXIF."""
    found = exif_focal(ctx.objects.get_head(key, EXIF_HEAD_BYTES), image_shape[1], image_shape[0])
    return found.focal_px if found else None


_prepared: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()


def cached_prepared(ctx: WorkerContext, key: str, max_pixels: int, spec: ScanSpec) -> np.ndarray:
    """The photo at `key` as the plan's coordinates refer to it (the engine's
    prepare_images: without lens distortion when the spec's camera has some), cached too."""
    decoded = cached_image(ctx, key, max_pixels)
    if spec.camera is None or not spec.camera.has_distortion:
        return decoded
    if (key, max_pixels) not in _prepared:
        undistorted = prepare_images(spec.camera, [decoded])[0]
        undistorted.flags.writeable = False
        _prepared[key, max_pixels] = undistorted
        while len(_prepared) > _IMAGES:
            _prepared.popitem(last=False)
    return _prepared[key, max_pixels]


@lru_cache(maxsize=8)
def cached_plan(ctx: WorkerContext, key: str) -> tuple[ScanPlan, dict[str, Any]]:
    """The plan at `key` and what was stored beside it (shared: callers must not modify it)."""
    return loads_plan(ctx.objects.get_bytes(key))

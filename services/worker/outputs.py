"""Write an item's cloud (CSV, PLY), its display preview, the overlay picture of the fit and
report.json into the job's prefix.

The preview (``preview.ply``, at most ``prismcore.cloud.PREVIEW_POINTS`` points, binary PLY) is
what the web page's 3D view loads: a 20-million-point cloud would not fit a browser.

Each file is written to a spooled temporary file (in memory while small, on disk beyond), then
streamed to the object store, so a 20-million-point cloud does not sit in memory twice.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Callable
from typing import BinaryIO

import numpy as np
from prism_common.records import ItemResult

from prismcore import ScanResult, ScanSpec
from prismcore.cloud import decimate
from prismcore.overlay import overlay_from_report
from prismcore.writers import FILE_NAMES, encode_png, write_format, write_ply

from . import context
from .keys import frame_key, item_key

__all__ = ["item_result", "write_outputs"]

_SPOOL_BYTES = 64 * 2**20
_CONTENT_TYPES = {"csv": "text/csv", "ply": "application/octet-stream", "preview": "application/octet-stream",
                  "report": "application/json", "overlay": "image/png", "overlay_side": "image/png"}


def _put(key: str, kind: str, write: Callable[[BinaryIO], object]) -> float:
    """Write a file with `write` and upload it; returns the writing time in ms."""
    with tempfile.SpooledTemporaryFile(max_size=_SPOOL_BYTES) as spool:
        start = time.perf_counter()
        write(spool)  # type: ignore[arg-type]
        elapsed = (time.perf_counter() - start) * 1000
        spool.seek(0)
        context.objects().put_stream(key, spool, _CONTENT_TYPES[kind])  # type: ignore[arg-type]
    return elapsed


def write_outputs(job_id: str, item: int, spec: ScanSpec, result: ScanResult, images: list[np.ndarray], *,
                  frame: int | None = None) -> tuple[ItemResult, dict[str, str]]:
    """Write the formats the spec asks for, the preview, the overlay of the fit on each photo
    (`images`: the front photo, and the side photo in two-photo mode, as decoded), then
    report.json; returns the item's result and the object key of each file written ({"csv":
    key, "ply": key, "preview": key, "overlay": key, "report": key}); for a video's `frame`,
    under that frame's folder."""
    cloud, report = result.cloud, result.report
    overlays = {"overlay": "front"} | ({"overlay_side": "side"} if spec.two_photo else {})
    kinds = (*spec.formats, "preview", *overlays, "report")
    keys = {kind: item_key(job_id, item, FILE_NAMES[kind]) if frame is None
            else frame_key(job_id, item, frame, FILE_NAMES[kind]) for kind in kinds}
    for kind in spec.formats:
        ms = _put(keys[kind], kind, lambda f, kind=kind: write_format(kind, f, cloud, spec))
        report["timings_ms"][f"write_{kind}"] = round(ms, 3)
    preview = decimate(cloud)
    _put(keys["preview"], "preview", lambda f: write_ply(f, preview.points, preview.colors))
    started = time.perf_counter()
    for kind, photo in overlays.items():
        picture = overlay_from_report(images[0 if photo == "front" else 1], report, photo=photo)
        context.objects().put_bytes(keys[kind], encode_png(picture), _CONTENT_TYPES[kind])
    report["timings_ms"]["write_overlay"] = round((time.perf_counter() - started) * 1000, 3)
    text = (json.dumps(report, indent=2) + "\n").encode()
    context.objects().put_bytes(keys["report"], text, _CONTENT_TYPES["report"])
    return item_result(report), keys


def item_result(report: dict) -> ItemResult:
    """What the job record keeps of a report: the figures a client polls for."""
    camera = report.get("camera") or {}
    return ItemResult(points=report["points"], dimensions=report["dimensions"],
                      point_loss=report["point_loss"], warnings=report["warnings"],
                      uncertainty=report.get("uncertainty"),
                      focal_px=camera.get("focal_px"), focal_source=camera.get("focal_source"),
                      fit_rms_px=(report.get("fit") or {}).get("rms_px"),
                      side_face=report.get("side_face"))

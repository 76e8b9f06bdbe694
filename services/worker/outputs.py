"""Write an item's cloud (CSV, PLY), its display preview and report.json into the job's prefix.

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

from prism_common.records import ItemResult

from prismcore import ScanResult, ScanSpec
from prismcore.cloud import decimate
from prismcore.writers import FILE_NAMES, write_format, write_ply

from . import context
from .keys import frame_key, item_key

__all__ = ["write_outputs"]

_SPOOL_BYTES = 64 * 2**20
_CONTENT_TYPES = {"csv": "text/csv", "ply": "application/octet-stream", "preview": "application/octet-stream",
                  "report": "application/json"}


def _put(key: str, kind: str, write: Callable[[BinaryIO], object]) -> float:
    """Write a file with `write` and upload it; returns the writing time in ms."""
    with tempfile.SpooledTemporaryFile(max_size=_SPOOL_BYTES) as spool:
        start = time.perf_counter()
        write(spool)  # type: ignore[arg-type]
        elapsed = (time.perf_counter() - start) * 1000
        spool.seek(0)
        context.objects().put_stream(key, spool, _CONTENT_TYPES[kind])  # type: ignore[arg-type]
    return elapsed


def write_outputs(job_id: str, item: int, spec: ScanSpec, result: ScanResult, *,
                  frame: int | None = None) -> tuple[ItemResult, dict[str, str]]:
    """Write the formats the spec asks for, the preview, then report.json; returns the item's
    result and the object key of each file written ({"csv": key, "ply": key, "preview": key,
    "report": key}); for a video's `frame`, under that frame's folder."""
    cloud, report = result.cloud, result.report
    kinds = (*spec.formats, "preview", "report")
    keys = {kind: item_key(job_id, item, FILE_NAMES[kind]) if frame is None
            else frame_key(job_id, item, frame, FILE_NAMES[kind]) for kind in kinds}
    for kind in spec.formats:
        ms = _put(keys[kind], kind, lambda f, kind=kind: write_format(kind, f, cloud, spec))
        report["timings_ms"][f"write_{kind}"] = round(ms, 3)
    preview = decimate(cloud)
    _put(keys["preview"], "preview", lambda f: write_ply(f, preview.points, preview.colors))
    text = (json.dumps(report, indent=2) + "\n").encode()
    context.objects().put_bytes(keys["report"], text, _CONTENT_TYPES["report"])
    summary = ItemResult(points=report["points"], dimensions=report["dimensions"],
                         point_loss=report["point_loss"], warnings=report["warnings"])
    return summary, keys

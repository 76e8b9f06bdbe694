"""Write an item's cloud (CSV, PLY) and report.json into the job's prefix.

Each file is written to a spooled temporary file (in memory while small, on disk beyond), then
streamed to the object store, so a 20-million-point cloud does not sit in memory twice.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable
from typing import BinaryIO

from prism_common.records import ItemResult

from prismcore import ScanResult, ScanSpec
from prismcore.writers import FILE_NAMES, write_format

from . import context
from .keys import item_key

__all__ = ["write_outputs"]

_SPOOL_BYTES = 64 * 2**20
_CONTENT_TYPES = {"csv": "text/csv", "ply": "application/octet-stream", "report": "application/json"}


def _put(key: str, kind: str, write: Callable[[BinaryIO], float]) -> float:
    """Write a file with `write` and upload it; returns the writing time in ms."""
    with tempfile.SpooledTemporaryFile(max_size=_SPOOL_BYTES) as spool:
        elapsed = write(spool)  # type: ignore[arg-type]
        spool.seek(0)
        context.objects().put_stream(key, spool, _CONTENT_TYPES[kind])  # type: ignore[arg-type]
    return elapsed


def write_outputs(job_id: str, item: int, spec: ScanSpec,
                  result: ScanResult) -> tuple[ItemResult, dict[str, str]]:
    """Write the formats the spec asks for, then report.json; returns the item's result and
    the object key of each file written ({"csv": key, "ply": key, "report": key})."""
    cloud, report = result.cloud, result.report
    keys = {kind: item_key(job_id, item, FILE_NAMES[kind]) for kind in (*spec.formats, "report")}
    for kind in spec.formats:
        ms = _put(keys[kind], kind, lambda f, kind=kind: write_format(kind, f, cloud, spec))
        report["timings_ms"][f"write_{kind}"] = round(ms, 3)
    text = (json.dumps(report, indent=2) + "\n").encode()
    context.objects().put_bytes(keys["report"], text, _CONTENT_TYPES["report"])
    summary = ItemResult(points=report["points"], dimensions=report["dimensions"],
                         point_loss=report["point_loss"], warnings=report["warnings"])
    return summary, keys

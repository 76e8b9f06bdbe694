"""A scan's outputs in a folder: the engine's `write_outputs` into a folder sink."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prismcore import ScanResult, ScanSpec
from prismcore.formats import FILE_NAMES
from prismcore.outputs import DEFAULT_OVERLAY_FORMAT, Writer, report_bytes, write_outputs
from prismcore.report import ScanReport

__all__ = ["FolderSink", "write_report", "write_scan"]


class FolderSink:
    """A `prismcore.outputs.sink.Sink` that writes each file into `folder` (made if missing)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)

    def put(self, name: str, data: bytes | Writer, media_type: str) -> None:
        path = self.folder / name
        if isinstance(data, bytes):
            path.write_bytes(data)
            return
        # Written beside it and moved into place whole: a writer that refuses (a format that needs
        # a scale, say) leaves the folder as it was, a file of an earlier run included.
        part = path.with_name(f".{name}.part")
        try:
            with open(part, "wb") as f:
                data(f)
            part.replace(path)
        except BaseException:
            part.unlink(missing_ok=True)
            raise


def write_scan(result: ScanResult, spec: ScanSpec, out_dir: Path, images: list[np.ndarray],
               overlay_format: str = DEFAULT_OVERLAY_FORMAT, *, report: bool = False) -> dict[str, Path]:
    """Write the formats the spec asks for (the glb model textured from `images`: the front photo,
    and the side photo with two, as decoded) and the overlay of the fit on each photo in
    `overlay_format` (overlay.jpg by default; png or webp on request); returns {kind: path}, a kind
    per file (`prismcore.formats.output_files`, then overlay and overlay_side).

    The writers' timings go into the report's `timings_ms`; with `report` False the caller writes
    report.json (`write_report`) once everything it times is done.
    """
    names = write_outputs(result, FolderSink(out_dir), spec=spec, images=images,
                          overlay_format=overlay_format, report=report)
    return {kind: out_dir / name for kind, name in names.items()}


def write_report(report: ScanReport, out_dir: Path) -> Path:
    """report.json in `out_dir`; returns its path."""
    path = out_dir / FILE_NAMES["report"]
    path.write_bytes(report_bytes(report))
    return path

"""Write a scan's outputs into a folder: the cloud files and the overlay pictures of the fit."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from prismcore import ScanResult, ScanSpec
from prismcore.outputs import (
    DEFAULT_OVERLAY_FORMAT,
    encode_overlay,
    overlay_from_report,
    overlay_name,
    write_format,
)
from prismcore.spec import output_files
from prismcore.spec_fields import FILE_NAMES

__all__ = ["report_path", "write_outputs", "write_overlays"]


def write_outputs(result: ScanResult, spec: ScanSpec, out_dir: Path,
                  images: list[np.ndarray] | None = None) -> dict[str, Path]:
    """Write the formats the spec asks for (the cloud's, the glb model of the box, which is
    textured from `images`: the front photo, and the side photo with two, as decoded, and the
    part's CAD files: step writes part.step and part.step.json, drawing drawing.svg, .pdf and
    .dxf); returns {kind: path}, a kind per file (`prismcore.spec.output_files`).

    The writers' timings go into the report's `timings_ms`; the caller writes the report
    (with `report_path`) once everything it times is done.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for kind in output_files(spec.formats):
        paths[kind] = out_dir / FILE_NAMES[kind]
        ms = write_format(kind, paths[kind], result.cloud, spec, report=result.report, images=images)
        result.report["timings_ms"][f"write_{kind}"] = round(ms, 3)
    return paths


def write_overlays(report: dict, front: np.ndarray, side: np.ndarray | None,
                   out_dir: Path, fmt: str = DEFAULT_OVERLAY_FORMAT) -> dict[str, Path]:
    """Draw the fit on the photo (and on the side photo in two-photo mode) and write the pictures
    in `fmt` (overlay.jpg by default; png or webp on request).

    Returns {"overlay": path} plus {"overlay_side": path} with two photos; the time taken goes
    into the report's `timings_ms["write_overlay"]`.
    """
    started = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"overlay": out_dir / overlay_name("overlay", fmt)}
    paths["overlay"].write_bytes(encode_overlay(overlay_from_report(front, report, photo="front"), fmt))
    if side is not None and report["inputs"].get("side_image"):
        paths["overlay_side"] = out_dir / overlay_name("overlay_side", fmt)
        side_picture = overlay_from_report(side, report, photo="side")
        paths["overlay_side"].write_bytes(encode_overlay(side_picture, fmt))
    report["timings_ms"]["write_overlay"] = round((time.perf_counter() - started) * 1000, 3)
    return paths


def report_path(out_dir: Path) -> Path:
    return out_dir / FILE_NAMES["report"]

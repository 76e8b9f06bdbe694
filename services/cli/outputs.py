"""Write a scan's cloud files into a folder."""

from __future__ import annotations

from pathlib import Path

from prismcore import ScanResult, ScanSpec
from prismcore.writers import FILE_NAMES, write_format

__all__ = ["report_path", "write_outputs"]


def write_outputs(result: ScanResult, spec: ScanSpec, out_dir: Path) -> dict[str, Path]:
    """Write the cloud in the formats the spec asks for; returns {kind: path}.

    The writers' timings go into the report's `timings_ms`; the caller writes the report
    (with `report_path`) once everything it times is done.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for kind in spec.formats:
        paths[kind] = out_dir / FILE_NAMES[kind]
        ms = write_format(kind, paths[kind], result.cloud, spec)
        result.report["timings_ms"][f"write_{kind}"] = round(ms, 3)
    return paths


def report_path(out_dir: Path) -> Path:
    return out_dir / FILE_NAMES["report"]

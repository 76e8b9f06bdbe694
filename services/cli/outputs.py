"""Write a scan's outputs (cloud files and report.json) into a folder."""

from __future__ import annotations

import json
import time
from pathlib import Path

from prismcore import ScanResult, ScanSpec
from prismcore.writers import write_csv, write_ply

__all__ = ["write_outputs"]


def write_outputs(result: ScanResult, spec: ScanSpec, out_dir: Path) -> dict[str, Path]:
    """Write the formats the spec asks for plus report.json; returns {kind: path}.

    The writers' timings are added to the report's `timings_ms` before it is written.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    cloud, report = result.cloud, result.report
    paths: dict[str, Path] = {}
    if "csv" in spec.formats:
        start = time.perf_counter()
        paths["csv"] = out_dir / "cloud.csv"
        write_csv(paths["csv"], cloud.points, cloud.colors if spec.csv.colors else None,
                  header=spec.csv.header)
        report["timings_ms"]["write_csv"] = round((time.perf_counter() - start) * 1000, 3)
    if "ply" in spec.formats:
        start = time.perf_counter()
        paths["ply"] = out_dir / "cloud.ply"
        write_ply(paths["ply"], cloud.points, cloud.colors, ascii=spec.ply_ascii)
        report["timings_ms"]["write_ply"] = round((time.perf_counter() - start) * 1000, 3)
    paths["report"] = out_dir / "report.json"
    paths["report"].write_text(json.dumps(report, indent=2) + "\n")
    return paths

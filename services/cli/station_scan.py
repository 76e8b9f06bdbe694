"""`prism scan PHOTO --station station.json`: a part measured on a station, no click, no known edge.

The station's fit gives the dimensions; its seven derived points make the cloud, the overlay and
the other outputs as clicked points do, with the camera of the station.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, cast

from rich.console import Console

__all__ = ["scan_on_station"]

console = Console()


def scan_on_station(
    image: Path, station_file: Path, out: Path, formats: str = "csv,ply", max_pixels: int = 50_000_000
) -> dict[str, Any]:
    """Measure `image` on the station; write report.json and the outputs in `out`. Returns the report."""
    from prismcore.images import load_image
    from prismcore.station.scan import scan_on_station as scan

    from .outputs import report_path, write_outputs, write_overlays
    from .station_command import load_station

    started = time.perf_counter()
    station = load_station(station_file)
    photo = load_image(image, max_pixels=max_pixels)
    done = scan(photo, station, str(image), {
        "formats": [f.strip() for f in formats.split(",") if f.strip()], "max_pixels": max_pixels})
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    report = done.report
    if done.result is not None and done.spec is not None:
        paths = write_outputs(done.result, done.spec, out, [photo])
        paths.update(write_overlays(report, photo, None, out))
    station_report = report["station"]
    report["timings_ms"]["total"] = round((time.perf_counter() - started) * 1000, 3)
    paths["report"] = report_path(out)
    paths["report"].write_text(json.dumps(report, indent=2) + "\n")
    d, s = report["dimensions"], report["uncertainty"]
    position = cast("list[float]", station_report["position_mm"])  # [x, y] mm, as report() writes it
    console.print(
        f"[bold]station[/]  width {d['width']:.2f} ± {s['width']:.2f}  height {d['height']:.2f} ± "
        f"{s['height']:.2f}  depth {d['depth']:.2f} ± {s['depth']:.2f} mm  (position "
        f"{position[0]:.1f}, {position[1]:.1f} mm, yaw "
        f"{station_report['yaw_deg']:.1f} deg; outline {station_report['silhouette_residual_px']:.2f} px)",
        soft_wrap=True,
    )
    for warning in report["warnings"]:
        console.print(f"[yellow]warning:[/] {warning}", soft_wrap=True)
    wide = max(map(len, paths))
    for kind, path in paths.items():
        console.print(f"{kind:>{wide}}: {path}", soft_wrap=True)
    return report

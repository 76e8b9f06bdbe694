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

from prismcore import InputError, ScanSpec, parse_points

__all__ = ["scan_on_station"]

console = Console()


def scan_on_station(
    image: Path, station_file: Path, out: Path, formats: str = "csv,ply", max_pixels: int = 50_000_000
) -> dict[str, Any]:
    """Measure `image` on the station; write report.json and the outputs in `out`. Returns the report."""
    from prismcore.auto_points import scan_found
    from prismcore.images import load_image
    from prismcore.station.measure import measure_on_station

    from .outputs import report_path, write_outputs, write_overlays
    from .station_command import load_station

    started = time.perf_counter()
    station = load_station(station_file)
    photo = load_image(image, max_pixels=max_pixels)
    measured = measure_on_station(photo, station)
    station_report = measured.report()
    points = " ".join(f"{x:.2f},{y:.2f}" for x, y in measured.points)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    try:
        # The front face's vertical edge is the box's height: the scale the cloud is made at.
        spec = ScanSpec.model_validate(
            {
                "image": str(image),
                "points": parse_points(points),
                "side_face": measured.side_face,
                "camera": station.camera.model_dump(),
                "scale": {"kind": "edge", "edge": "height", "length_mm": measured.dimensions["height"]},
                "formats": [f.strip() for f in formats.split(",") if f.strip()],
                "max_pixels": max_pixels,
            }
        )
        result = scan_found(spec, None, photo, None, tiles=1)
        report = result.report
        paths = write_outputs(result, spec, out, [photo])
        paths.update(write_overlays(report, photo, None, out))
    except InputError as exc:  # the measurement stands; the cloud could not be made from its points
        report = {"warnings": [f"no cloud: the derived points were refused ({exc})"], "timings_ms": {}}
    engine_dims = report.get("dimensions")
    report["engine_dimensions"] = engine_dims  # the engine's own reading from the derived points
    report["dimensions"] = station_report["dimensions"]
    report["uncertainty"] = station_report["uncertainty"]
    report["scale_source"] = "station"
    report["points_source"] = "station"
    report["station"] = station_report
    report["warnings"] = list(measured.warnings) + list(report.get("warnings", []))
    report.setdefault("timings_ms", {})["station"] = round(sum(measured.timings_ms.values()), 3)
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

"""`prism scan PHOTO --station station.json` (or `--board board.json`, hand-held): a part measured
with no click and no known edge.

The station's (or the board's) fit gives the dimensions; its seven derived points make the cloud,
the overlay and the other outputs as clicked points do, with the camera measured with.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from .console import rich_console as console

if TYPE_CHECKING:
    import numpy as np

    from prismcore.camera import CameraModel
    from prismcore.errors import InputError, PartRefusedError
    from prismcore.report import ScanReport, StationBlock
    from prismcore.station import Station, StationScan

__all__ = ["certification_line", "scan_on_board_photo", "scan_on_station"]


def _spec_extra(formats: str, max_pixels: int) -> dict[str, Any]:
    return {"formats": [f.strip() for f in formats.split(",") if f.strip()], "max_pixels": max_pixels}


def scan_on_station(
    image: Path, station_file: Path | Station, out: Path, formats: str = "csv,ply",
    max_pixels: int = 50_000_000, overlay_format: str = "jpeg",
    tolerance_mm: float | list[float] | None = None, nominal: list[float] | None = None,
) -> ScanReport:
    """Measure `image` on the station (its file, or the station a batch loaded once); write
    report.json and the outputs in `out`. Returns the report. tolerance_mm (--tolerance-mm) is what
    the camera's drift is judged against, and with `nominal` (--nominal) the dimensions' verdicts."""
    from prismcore.errors import PartRefusedError
    from prismcore.io import load_image
    from prismcore.quality import report_quality
    from prismcore.station import scan_on_station as scan

    from .station_command import load_station

    started = time.perf_counter()
    station = load_station(station_file) if isinstance(station_file, Path) else station_file
    photo = load_image(image, max_pixels=max_pixels)
    judged = cast("float | tuple[float, float, float] | None",
                  tuple(tolerance_mm) if isinstance(tolerance_mm, list) else tolerance_mm)
    try:
        done = scan(photo, station, str(image), _spec_extra(formats, max_pixels), judged)
    except PartRefusedError as exc:
        raise _shown(exc, out, overlay_format) from None
    if nominal is not None:  # the verdicts judge the station's dimensions, as the service's do
        done.report.quality = report_quality(done.report, nominal, tolerance_mm)
    return _write(done, photo, out, started, overlay_format)


def scan_on_board_photo(
    image: Path, board_file: Path, out: Path, camera: CameraModel | None = None, formats: str = "csv,ply",
    max_pixels: int = 50_000_000, overlay_format: str = "jpeg",
) -> ScanReport:
    """Measure a hand-held `image` of a part lying on the board; write the outputs in `out`."""
    from prismcore.errors import PartRefusedError
    from prismcore.io import load_image
    from prismcore.station import scan_on_board

    from .station_command import load_board

    started = time.perf_counter()
    board = load_board(board_file)
    photo = load_image(image, max_pixels=max_pixels)
    try:
        done = scan_on_board(photo, board, camera, str(image), _spec_extra(formats, max_pixels))
    except PartRefusedError as exc:
        raise _shown(exc, out, overlay_format) from None
    return _write(done, photo, out, started, overlay_format)


def _shown(refused: PartRefusedError, out: Path, overlay_format: str) -> InputError:
    """The refusal, its overlay (what was taken for the part, and why refused) written in `out`
    and named in its words."""
    from prismcore.errors import InputError
    from prismcore.outputs import encode_overlay, overlay_name, refusal_overlay

    if refused.photo is None:
        return refused
    path = out / overlay_name("overlay", overlay_format)
    try:
        picture = refusal_overlay(refused.photo, refused.taken, str(refused))
        out.mkdir(parents=True, exist_ok=True)
        path.write_bytes(encode_overlay(picture, overlay_format))
    except (OSError, InputError):  # the refusal's words matter more than its picture
        return refused
    return InputError(f"{refused} ({path} shows what was taken for the part)")


def certification_line(station: StationBlock) -> str:
    """'station verified on 2026-12-06: bias ...; camera moved 0.1 px (0.0 mm) since calibration'."""
    assert station.verification is not None and station.drift is not None
    return (f"station {station.verification.text}; camera moved {station.drift.shift_px:.1f} px "
            f"({station.drift.shift_mm:.1f} mm on the support) since calibration")


def _write(done: StationScan, photo: np.ndarray, out: Path, started: float,
           overlay_format: str = "jpeg") -> ScanReport:
    """Write the outputs, the overlay in `overlay_format` (jpeg, png or webp) and report.json."""
    from .outputs import write_report, write_scan
    from .photo_scan import quality_lines

    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    report = done.report
    if done.result is not None and done.spec is not None:
        paths = write_scan(done.result, done.spec, out, [photo], overlay_format)
    station = report.station
    assert station is not None
    report.timings_ms["total"] = round((time.perf_counter() - started) * 1000, 3)
    paths["report"] = write_report(report, out)
    d, s = report.dimensions, station.uncertainty
    position = station.position_mm
    console().print(f"[bold]{report.scale_source}[/]  width {d.width:.2f} ± {s.width:.2f}  height "
                  f"{d.height:.2f} ± {s.height:.2f}  depth {d.depth:.2f} ± {s.depth:.2f} mm  "
                  f"(position {position[0]:.1f}, {position[1]:.1f} mm, "
                  f"yaw {station.yaw_deg:.1f} deg; "
                  f"outline {station.silhouette_residual_px:.2f} px)", soft_wrap=True)
    if station.verification is not None:  # a station's (a hand-held board has none)
        console().print(certification_line(station), markup=False, soft_wrap=True)
    for line in quality_lines(report.quality):
        console().print(line, soft_wrap=True)
    for warning in report.warnings:
        console().print(f"[yellow]warning:[/] {warning}", soft_wrap=True)
    wide = max(map(len, paths))
    for kind, path in paths.items():
        console().print(f"{kind:>{wide}}: {path}", soft_wrap=True)
    return report

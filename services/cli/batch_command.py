"""`prism scan`'s batches (one part a photo, in one process; `scan_batch` runs them): photos on a
station, photos on a board (hand-held), and a points table's photos, each spec run by the runner
of its kind (`scan_runners.RUNNERS`). Each returns how many photos failed; bad input (a missing
photo, a bad station, board or table) raises InputError before anything is measured."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from prismcore.errors import InputError

from .scan_batch import BatchPhoto, folders, read_points_table, report_of, run_batch
from .scan_runners import RUNNERS, RunOptions

if TYPE_CHECKING:
    from prismcore.camera import CameraModel
    from prismcore.report import ScanReport
    from prismcore.spec import ScanSpec

__all__ = ["board_batch", "station_batch", "table_batch"]


def _photos(images: list[Path]) -> list[BatchPhoto]:
    missing = [str(p) for p in images if not p.is_file()]
    if missing:
        raise InputError(f"no photo {', '.join(map(repr, missing))}: nothing was measured")
    return [BatchPhoto(path, folder) for path, folder in zip(images, folders(images), strict=True)]


def station_batch(images: list[Path], station_file: Path, out: Path, *, formats: str, max_pixels: int,
                  overlay_format: str, tolerance_mm: float | list[float] | None,
                  nominal: list[float] | None) -> int:
    """The photos measured on the station (loaded once)."""
    from .station_command import load_station
    from .station_scan import scan_on_station

    photos = _photos(images)
    station = load_station(station_file)
    return run_batch(photos, out, lambda photo, folder: scan_on_station(
        photo.path, station, folder, formats=formats, max_pixels=max_pixels,
        overlay_format=overlay_format, tolerance_mm=tolerance_mm, nominal=nominal))


def board_batch(images: list[Path], board_file: Path, out: Path, *, camera: CameraModel | None,
                formats: str, max_pixels: int, overlay_format: str) -> int:
    """Hand-held photos, each part lying on the board."""
    from .station_command import load_board
    from .station_scan import scan_on_board_photo

    photos = _photos(images)
    load_board(board_file)  # a bad board.json is bad input, not every photo's failure
    return run_batch(photos, out, lambda photo, folder: scan_on_board_photo(
        photo.path, board_file, folder, camera=camera, formats=formats, max_pixels=max_pixels,
        overlay_format=overlay_format))


def _row_flags(row: dict[str, str], flags: dict[str, Any]) -> dict[str, Any]:
    """The command line's spec flags with a table row's own put in (a row's scale replaces the
    command line's: a spec has one)."""
    from .scan_batch import PHOTO_FLAGS

    given = dict(flags)
    if any(k in row for k in ("width_mm", "height_mm", "depth_mm", "distance_mm", "mm_per_px")):
        given.update(dict.fromkeys(("width_mm", "height_mm", "depth_mm", "distance_mm", "mm_per_px")))
    for name in PHOTO_FLAGS:
        if name not in row:
            continue
        value: Any = row[name]
        if name in ("width_mm", "height_mm", "depth_mm", "distance_mm", "focal_px"):
            try:
                value = float(value)
            except ValueError:
                raise InputError(f"{name} {value!r}: expected a number") from None
        given[name] = value
    return given


def table_batch(images: list[Path], table: Path, out: Path, *, spec_flags: dict[str, Any],
                run: RunOptions) -> int:
    """A points table's photos, each measured alone with its row's points (and options)."""
    from prismcore.io import is_video

    from .scan_flags import spec_from_flags

    def spec_for(path: Path, row: dict[str, str]) -> ScanSpec:
        if is_video(path):
            raise InputError(f"{path} is a video: measure it alone (prism scan VIDEO --points ...)")
        if not row.get("points"):
            raise InputError("no points: give seven points \"x1,y1 x2,y2 ...\" or auto")
        return spec_from_flags(path, row.get("points"), **_row_flags(row, spec_flags))

    photos = read_points_table(table, images, spec_for)

    def measure(photo: BatchPhoto, folder: Path) -> ScanReport:
        assert photo.spec is not None
        RUNNERS[photo.spec.kind](photo.spec, Path("."), dataclasses.replace(
            run, out=folder, started=time.perf_counter()))
        return report_of(folder)

    return run_batch(photos, out, measure)

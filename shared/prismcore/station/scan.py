"""A photo scanned on a station (or on a board, hand-held): the measurement, and the cloud made
from its seven derived points as from clicks, in one report. Shared by `prism scan` and the worker."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.scan.pipeline import ScanResult, run_scan
from prismcore.spec import ScanSpec, parse_points
from prismcore.station.board import BoardSpec
from prismcore.station.calibrate import Station
from prismcore.station.measure import StationMeasurement, measure_on_station

__all__ = ["StationScan", "scan_on_board", "scan_on_station", "station_spec"]


@dataclass
class StationScan:
    """measured : the measurement. result : the cloud's scan, None when the engine refused the
    derived points (the measurement stands, with a warning). report : report.json."""

    measured: StationMeasurement
    spec: ScanSpec | None
    result: ScanResult | None
    report: dict[str, Any]


def station_spec(measured: StationMeasurement, image: str, extra: dict[str, Any] | None = None) -> ScanSpec:
    """The scan spec of the derived points: the camera measured with, the fitted height as the
    front face's known edge (the front face's vertical edge is the box's height)."""
    if measured.camera is None:
        raise InputError("the measurement names no camera")
    points = " ".join(f"{x:.2f},{y:.2f}" for x, y in measured.points)
    return ScanSpec.model_validate(
        {
            "image": image,
            "points": parse_points(points),
            "side_face": measured.side_face,
            "camera": measured.camera.model_dump(),
            "scale": {"kind": "edge", "edge": "height", "length_mm": measured.dimensions["height"]},
            **(extra or {}),
        }
    )


def _with_cloud(
    measured: StationMeasurement, photo: np.ndarray, image: str, extra: dict[str, Any] | None, source: str
) -> StationScan:
    spec: ScanSpec | None = None
    result: ScanResult | None = None
    try:
        spec = station_spec(measured, image, extra)
        result = run_scan(spec, photo, None)
        report = result.report
    except InputError as exc:  # the measurement stands; the cloud could not be made from its points
        report = {"warnings": [f"no cloud: the derived points were refused ({exc})"], "timings_ms": {}}
    station_report = measured.report()
    report["engine_dimensions"] = report.get("dimensions")  # the engine's reading of the derived points
    report["dimensions"] = station_report["dimensions"]
    report["uncertainty"] = station_report["uncertainty"]
    report["scale_source"] = source
    report["points_source"] = source
    report["station"] = station_report
    report["warnings"] = list(measured.warnings) + list(report.get("warnings", []))
    report.setdefault("timings_ms", {})["station"] = round(sum(measured.timings_ms.values()), 3)
    return StationScan(measured, spec, result, report)


def scan_on_station(
    photo: np.ndarray, station: Station, image: str = "photo", extra: dict[str, Any] | None = None
) -> StationScan:
    """Measure the part in `photo` (RGB (H, W, 3) uint8) on `station`, then make its cloud.

    extra : more ScanSpec fields for the cloud (formats, max_pixels, ...).

    Raises
    ------
    InputError
        As :func:`measure_on_station`: the photo cannot be measured on this station.
    """
    return _with_cloud(measure_on_station(photo, station), photo, image, extra, "station")


def scan_on_board(
    photo: np.ndarray,
    board: BoardSpec,
    camera: CameraModel | None = None,
    image: str = "photo",
    extra: dict[str, Any] | None = None,
) -> StationScan:
    """A hand-held photo of a part lying on `board`: as :func:`scan_on_station`, with the board in
    the photo as the station (``scale_source`` "board")."""
    from prismcore.station.handheld import measure_on_board

    return _with_cloud(measure_on_board(photo, board, camera), photo, image, extra, "board")

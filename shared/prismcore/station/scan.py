"""A photo scanned on a station: the station's measurement, and the cloud made from its seven
derived points as from clicks, in one report. Shared by `prism scan --station` and the worker."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..pipeline import ScanResult, run_scan
from ..spec import ScanSpec, parse_points
from .calibrate import Station
from .measure import StationMeasurement, measure_on_station

__all__ = ["StationScan", "scan_on_station", "station_spec"]


@dataclass
class StationScan:
    """measured : the station's measurement. result : the cloud's scan, None when the engine
    refused the derived points (the measurement stands, with a warning). report : report.json."""

    measured: StationMeasurement
    spec: ScanSpec | None
    result: ScanResult | None
    report: dict[str, Any]


def station_spec(measured: StationMeasurement, station: Station, image: str,
                 extra: dict[str, Any] | None = None) -> ScanSpec:
    """The scan spec of the derived points: the station's camera, the fitted height as the front
    face's known edge (the front face's vertical edge is the box's height)."""
    points = " ".join(f"{x:.2f},{y:.2f}" for x, y in measured.points)
    return ScanSpec.model_validate({
        "image": image, "points": parse_points(points), "side_face": measured.side_face,
        "camera": station.camera.model_dump(),
        "scale": {"kind": "edge", "edge": "height", "length_mm": measured.dimensions["height"]},
        **(extra or {})})


def scan_on_station(photo: np.ndarray, station: Station, image: str = "photo",
                    extra: dict[str, Any] | None = None) -> StationScan:
    """Measure the part in `photo` (RGB (H, W, 3) uint8) on `station`, then make its cloud.

    extra : more ScanSpec fields for the cloud (formats, max_pixels, ...).

    Raises
    ------
    InputError
        As :func:`measure_on_station`: the photo cannot be measured on this station.
    """
    measured = measure_on_station(photo, station)
    spec: ScanSpec | None = None
    result: ScanResult | None = None
    try:
        spec = station_spec(measured, station, image, extra)
        result = run_scan(spec, photo, None)
        report = result.report
    except InputError as exc:  # the measurement stands; the cloud could not be made from its points
        report = {"warnings": [f"no cloud: the derived points were refused ({exc})"], "timings_ms": {}}
    station_report = measured.report()
    report["engine_dimensions"] = report.get("dimensions")  # the engine's reading of the derived points
    report["dimensions"] = station_report["dimensions"]
    report["uncertainty"] = station_report["uncertainty"]
    report["scale_source"] = "station"
    report["points_source"] = "station"
    report["station"] = station_report
    report["warnings"] = list(measured.warnings) + list(report.get("warnings", []))
    report.setdefault("timings_ms", {})["station"] = round(sum(measured.timings_ms.values()), 3)
    return StationScan(measured, spec, result, report)

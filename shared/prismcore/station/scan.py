"""A photo scanned on a station (or on a board, hand-held): the measurement, and the cloud made
from its seven derived points as from clicks, in one report. Shared by `prism scan` and the worker.

The report is the station's own (`station_report`): its dimensions and their sigma are the
station's fit; the cloud's scan of the derived points adds what it made (the cloud, its faces, the
camera, the fit to the points) and its own reading of the size, kept as ``engine_dimensions``."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.report import ScanReport, StationBlock
from prismcore.scan.pipeline import ScanResult, run_scan
from prismcore.spec import ScanSpec, parse_points
from prismcore.station.board import BoardSpec
from prismcore.station.calibrate import Station
from prismcore.station.measure import StationMeasurement, measure_on_station

__all__ = ["StationScan", "certify", "scan_on_board", "scan_on_station", "station_report", "station_spec"]


@dataclass
class StationScan:
    """measured : the measurement. result : the cloud's scan, None when the engine refused the
    derived points (the measurement stands, with a warning); its report is `report`.
    report : report.json, the station's (`station_report`)."""

    measured: StationMeasurement
    spec: ScanSpec | None
    result: ScanResult | None
    report: ScanReport


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


def station_report(measured: StationMeasurement, source: Literal["station", "board"],
                   cloud: ScanReport | str, certification: dict[str, Any] | None = None) -> ScanReport:
    """report.json of a photo measured on a station (`source` "station") or a board ("board").

    The dimensions and their sigma are the station's fit (`measured`, with `certification`'s
    verification and drift on a station); `cloud` is the report of the cloud made from the
    derived points, whose fields (points, faces, camera, fit, ...) the report keeps, its reading
    of the size as ``engine_dimensions``; or, when the engine refused those points, the reason.
    """
    block = StationBlock.model_validate({**measured.report(), **(certification or {})})
    if isinstance(cloud, str):
        made: dict[str, Any] = {}
        engine, warnings, timings = None, [f"no cloud: the derived points were refused ({cloud})"], {}
    else:  # every field the cloud's scan set, as it set it
        made = {name: getattr(cloud, name) for name in cloud.model_fields_set}
        engine, warnings, timings = cloud.dimensions, cloud.warnings, cloud.timings_ms
    return ScanReport.model_validate({
        **made,
        "engine_dimensions": engine,  # the engine's reading of the derived points
        "dimensions": block.dimensions,
        "uncertainty": block.uncertainty,
        "scale_source": source,
        "points_source": source,
        "station": block,
        "warnings": list(measured.warnings) + warnings,
        "timings_ms": {**timings, "station": round(sum(measured.timings_ms.values()), 3)},
    })


def _with_cloud(
    measured: StationMeasurement,
    photo: np.ndarray,
    image: str,
    extra: dict[str, Any] | None,
    source: Literal["station", "board"],
    certification: dict[str, Any] | None = None,
) -> StationScan:
    spec: ScanSpec | None = None
    result: ScanResult | None = None
    try:
        spec = station_spec(measured, image, extra)
        result = run_scan(spec, photo, None)
    except InputError as exc:  # the measurement stands; the cloud could not be made from its points
        report = station_report(measured, source, str(exc), certification)
    else:
        report = station_report(measured, source, result.report, certification)
        result = replace(result, report=report)
    return StationScan(measured, spec, result, report)


def scan_on_station(
    photo: np.ndarray,
    station: Station,
    image: str = "photo",
    extra: dict[str, Any] | None = None,
    tolerance_mm: float | tuple[float, float, float] | None = None,
) -> StationScan:
    """Measure the part in `photo` (RGB (H, W, 3) uint8) on `station`, then make its cloud.

    extra : more ScanSpec fields for the cloud (formats, max_pixels, ...). tolerance_mm : the
    measurement's T of +-T (one, or width, height, depth), which the drift's cost is judged
    against (`certify.drift`). The report's ``station`` says the station's verification and the
    camera's drift since calibration, warned when not verified or when the drift costs too much.

    Raises
    ------
    InputError
        As :func:`measure_on_station`: the photo cannot be measured on this station.
    """
    measured = measure_on_station(photo, station)
    certification = certify(measured, station, tolerance_mm)
    return _with_cloud(measured, photo, image, extra, "station", certification)


def certify(measured: StationMeasurement, station: Station,
            tolerance_mm: float | tuple[float, float, float] | None = None) -> dict[str, Any]:
    """The station's verification status and the camera's drift as `measured` states them
    (report.json's ``station.verification`` and ``station.drift``); their warnings are added to
    `measured.warnings`."""
    from prismcore.station.certify import drift, verification_status

    reg = measured.registration
    moved = drift(station, reg.homography, reg.shift_px, measured.position_mm, measured.dimensions,
                  measured.uncertainty, tolerance_mm)
    status = verification_status(station.verification, moved["moved"], moved["shift_px"], moved["shift_mm"])
    if status["warning"]:
        measured.warnings.append(status["warning"])
    if moved["reverify"]:
        worst = max(moved["cost_mm"], key=lambda k: moved["cost_mm"][k] / max(moved["allowed_mm"][k], 1e-12))
        measured.warnings.append(
            f"the camera moved {moved['shift_px']:.1f} px ({moved['shift_mm']:.1f} mm on the support) since "
            f"calibration: unless the re-registration followed it exactly, it may move the {worst} by "
            f"{moved['cost_mm'][worst]:.2f} mm, over a third of the tolerance "
            f"({moved['allowed_mm'][worst]:.2f} mm, from {moved['tolerance_from']}); verify the station "
            "again (prism station verify)")
    return {"verification": status, "drift": moved}


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

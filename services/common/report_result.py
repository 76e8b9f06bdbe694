"""What a results table keeps of a report.json: the item result (`ItemResult`) a job record holds,
made by the worker for each item and by `prism scan`'s local batch for each photo, read from the
report's model (`prismcore.report.ScanReport`).

Imports the engine's outputs face and the contract (not the API's business: the API reads records only).
"""

from __future__ import annotations

from typing import Any

from prismcore.outputs import given_dimension
from prismcore.report import ScanReport

from .records import ItemResult

__all__ = ["item_result", "station_check"]


def item_result(report: ScanReport) -> ItemResult:
    """What the job record keeps of a report: the figures a client polls for (a station's report
    whose derived points made no cloud: no points, no point loss)."""
    camera, fit, found = report.camera, report.fit, report.auto_points
    return ItemResult(points=report.points or 0, dimensions=report.dimensions.model_dump(),
                      point_loss=report.point_loss or 0.0, warnings=report.warnings,
                      uncertainty=None if report.uncertainty is None else report.uncertainty.model_dump(),
                      focal_px=None if camera is None else camera.focal_px,
                      focal_source=None if camera is None else camera.focal_source,
                      fit_rms_px=None if fit is None else fit.rms_px,
                      side_face=report.side_face,
                      quality=None if report.quality is None else report.quality.model_dump(),
                      points_source=report.points_source or "clicked",
                      points_confidence=None if found is None else found.confidence,
                      given_dimension=given_dimension(report),
                      reference_points=(report.inputs or {}).get("points"),
                      station=station_check(report))


def station_check(report: ScanReport) -> dict[str, Any] | None:
    """A station measurement's verification status and drift (report.json's ``station``); None for
    others (a hand-held board's measurement has no station to verify)."""
    station = report.station
    if station is None or station.verification is None or station.drift is None:
        return None
    return {"verification": station.verification.model_dump(), "drift": station.drift.model_dump()}

"""What a results table keeps of a report.json: the item result (`ItemResult`) a job record holds,
made by the worker for each item and by `prism scan`'s local batch for each photo.

Imports the engine's outputs face (not the API's business: the API reads records only).
"""

from __future__ import annotations

from typing import Any

from prismcore.outputs import given_dimension

from .records import ItemResult

__all__ = ["item_result", "station_check"]


def item_result(report: dict[str, Any]) -> ItemResult:
    """What the job record keeps of a report: the figures a client polls for."""
    camera = report.get("camera") or {}
    return ItemResult(points=report["points"], dimensions=report["dimensions"],
                      point_loss=report["point_loss"], warnings=report["warnings"],
                      uncertainty=report.get("uncertainty"),
                      focal_px=camera.get("focal_px"), focal_source=camera.get("focal_source"),
                      fit_rms_px=(report.get("fit") or {}).get("rms_px"),
                      side_face=report.get("side_face"), quality=report.get("quality"),
                      points_source=report.get("points_source", "clicked"),
                      points_confidence=(report.get("auto_points") or {}).get("confidence"),
                      given_dimension=given_dimension(report),
                      reference_points=(report.get("inputs") or {}).get("points"),
                      station=station_check(report))


def station_check(report: dict[str, Any]) -> dict[str, Any] | None:
    """A station measurement's verification status and drift (report.json's ``station``); None for
    others (a hand-held board's measurement has no station to verify)."""
    found = report.get("station") or {}
    if "verification" not in found:
        return None
    return {"verification": found["verification"], "drift": found["drift"]}

"""Stored stations: a tenant's calibrated cameras-over-supports, kept in the object store alone.

``stations/{tenant hash}/{id}/station.json`` is the station as `prism station calibrate` writes
it (`prismcore.station.Station`, the plate as base64 PNG inside); beside it ``summary.json``, the
public summary (`StationPublic`), small enough to be read for a listing or a job's validation
without the plate. The summary is written last, so a station is listed (and usable) only once
both are stored; deleting removes the summary first. Keys hold the tenant's hash: another
tenant's id names nothing. Stations are not swept by the retention: they stay until deleted.

The API writes and deletes stations (`prism_api.routes.stations`); the worker reads station.json
(`prism_worker.station_item`), keyed by its ETag in a per-process cache.
"""

from __future__ import annotations

import re
from datetime import datetime
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, Field

if TYPE_CHECKING:
    from prismcore.station import Station

    from .storage import ObjectStore

__all__ = ["STATION_ID", "StationPublic", "delete_station", "get_summary", "list_summaries", "put_station",
           "station_key", "station_summary", "summary_key"]

STATION_ID = re.compile(r"^[0-9a-f]{32}$")


class StationPublic(BaseModel):
    """A stored station, without its plate: what it was calibrated with and how well."""

    id: str = Field(description="Name it in a job item as `\"station\": ID`.")
    name: str | None = Field(default=None, description="Your own name for it, if given.")
    created_at: datetime
    image_width: int = Field(description="The camera's image size, px: the photos must have it.")
    image_height: int
    board: dict[str, Any] = Field(description="The calibration board (board.json's fields).")
    camera: dict[str, Any] = Field(description="fx, fy, cx, cy (px) and the lens distortion.")
    calibration: dict[str, Any] = Field(description="How the intrinsics were found: source "
                                        "(photos or camera), rms_px, views, corners.")
    plane_rms_px: float = Field(description="RMS of the plane photo's board corners about the "
                                "fitted support plane, px.")
    plane_corners: int = Field(description="Board corners the support plane was fitted to.")
    camera_height_mm: float = Field(description="The camera's height above the support, mm.")
    has_plate: bool = Field(description="A photo of the empty support is stored (parts are found "
                            "against it; without one every scan on the station is refused).")
    size: int = Field(description="Bytes of station.json (the plate included).")


class StationList(BaseModel):
    stations: list[StationPublic] = Field(description="Newest first.")


def _folder(tenant: str, *station_id: str) -> str:
    # Imported here: the CLI's client reads the models above without boto3.
    from .storage import object_key
    from .upload_keys import tenant_hash

    return object_key("stations", tenant_hash(tenant), *station_id)


def station_key(tenant: str, station_id: str) -> str:
    return f"{_folder(tenant, station_id)}/station.json"


def summary_key(tenant: str, station_id: str) -> str:
    return f"{_folder(tenant, station_id)}/summary.json"


def station_summary(station: Station, station_id: str, *, name: str | None, created_at: datetime,
                    size: int) -> StationPublic:
    camera = station.camera
    calibration = {k: v for k, v in station.calibration.items() if k != "views_left_out"}
    return StationPublic(
        id=station_id, name=name, created_at=created_at, image_width=camera.image_width,
        image_height=camera.image_height, board=station.board.describe(),
        camera={"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                "dist": list(camera.dist)},
        calibration=calibration, plane_rms_px=station.plane.rms_px, plane_corners=station.plane.corners,
        camera_height_mm=round(-float(station.plane.camera_centre()[2]), 1),
        has_plate=station.plate_png is not None, size=size)


def put_station(objects: ObjectStore, tenant: str, station_id: str, document: bytes,
                summary: StationPublic) -> None:
    """Store station.json, then its summary (which makes it visible)."""
    objects.put_bytes(station_key(tenant, station_id), document, "application/json")
    objects.put_bytes(summary_key(tenant, station_id), summary.model_dump_json(indent=2).encode(),
                      "application/json")


def get_summary(objects: ObjectStore, tenant: str, station_id: str) -> StationPublic | None:
    """The tenant's station `station_id`, or None (unknown, malformed, or another tenant's)."""
    if not STATION_ID.match(station_id):
        return None
    found = objects.get_json(summary_key(tenant, station_id))
    return None if found is None else StationPublic.model_validate(found)


def list_summaries(objects: ObjectStore, tenant: str) -> list[StationPublic]:
    """The tenant's stations, newest first."""
    prefix = _folder(tenant) + "/"
    found = []
    for key in objects.list_keys(prefix):
        if key.endswith("/summary.json") and (doc := objects.get_json(key)) is not None:
            found.append(StationPublic.model_validate(doc))
    return sorted(found, key=lambda s: s.created_at, reverse=True)


def delete_station(objects: ObjectStore, tenant: str, station_id: str) -> bool:
    """Delete the station; False when the tenant has none of that id."""
    if get_summary(objects, tenant, station_id) is None:
        return False
    objects.delete_keys([summary_key(tenant, station_id)])
    objects.delete_keys([station_key(tenant, station_id)])
    return True

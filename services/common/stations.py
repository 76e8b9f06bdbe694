"""Stored stations: a tenant's calibrated cameras-over-supports, kept in the object store alone.

``stations/{tenant hash}/{id}/station.json`` is the station as `prism station calibrate` writes
it (`prismcore.station.Station`, the plate as base64 PNG inside); beside it ``summary.json``, the
public summary (`StationPublic`), small enough to be read for a listing or a job's validation
without the plate. The summary is written last, so a station is listed (and usable) only once
both are stored; deleting removes the summary first. Keys hold the tenant's hash: another
tenant's id names nothing. Stations are not swept by the retention: they stay until deleted.
``verifications/{date}-{ns}-{id}.json`` beside them keep the station's verifications with a reference
part (`VerificationPublic`, its history), the last one also in station.json and, in short, the
summary; deleting the station deletes them.

The API writes and deletes stations (`prism_api.routes.stations`); the worker reads station.json
(`prism_worker.station_item`), keyed by its ETag in a per-process cache.
"""

from __future__ import annotations

import re
import time
from datetime import datetime
from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, Field

if TYPE_CHECKING:
    from prismcore.station import Station

    from .storage import ObjectStore

__all__ = ["STATION_ID", "CapabilityPublic", "DimensionVerificationPublic", "StationPublic",
           "StationStatusPublic", "VerificationList", "VerificationPublic", "delete_station", "get_summary",
           "list_summaries",
           "list_verifications", "put_station", "put_verification", "station_key", "station_summary",
           "summary_key", "verification_prefix"]

STATION_ID = re.compile(r"^[0-9a-f]{32}$")


class CapabilityPublic(BaseModel):
    """What the station can measure (`prismcore.station.capability`)."""

    mm_per_px: dict[str, float] = Field(description="The support's scale, mm per px, at its edge nearest "
                                        "the camera (`near`) and farthest from it (`far`).")
    min_part_mm: float = Field(description="The smallest part it measures without a too-small warning: "
                               "a side spanning 60 px at the far edge.")
    min_tolerance_mm: float = Field(description="The smallest T of +-T it holds at the far edge: %GRR "
                                    "(6 sigma / 2T) at most 30 % with the station's stated sigma there.")
    min_tolerance_near_mm: float = Field(description="The same at the near edge.")
    rule: str = Field(description="The rule above in words.")


class StationStatusPublic(BaseModel):
    """The station's last verification with a reference part, in short."""

    status: Literal["verified", "not verified"] = Field(description="`not verified` when there is none or "
                                                       "the last one failed.")
    text: str = Field(description="In words: 'verified on DATE: bias ..., repeatability ...'.")
    date: datetime | None = Field(description="When the last verification was made (UTC); null if none.")
    tolerance_mm: float | None = Field(description="The T of +-T it was judged against.")
    bias_mm: dict[str, float] | None = Field(description="Each dimension's bias (mean error).")
    repeatability_mm: dict[str, float] | None = Field(description="Each dimension's repeatability.")


class DimensionVerificationPublic(BaseModel):
    """One dimension's figures over the reference part's placements, mm."""

    reference_mm: float
    mean_mm: float = Field(description="The mean measured value.")
    bias_mm: float = Field(description="The mean error (measured - reference).")
    bias_ci95_mm: tuple[float, float] = Field(
        description="The bias's 95 % confidence interval (Student's t).")
    repeatability_mm: float = Field(description="The errors' sample standard deviation over the placements.")
    errors_mm: list[float] = Field(description="Each placement's error.")
    sigmas_mm: list[float] = Field(description="Each placement's stated one sigma.")
    within_3_sigma: list[bool] = Field(description="Each placement's error within 3 x its stated sigma.")
    grr_percent: float | None = Field(description="%GRR = 6 x repeatability / 2T x 100; null without a "
                                      "tolerance.")
    verified: bool
    failures: list[str] = Field(description="The rule's clauses this dimension fails.")


class VerificationPublic(BaseModel):
    """A verification of the station with a reference part (`prism station verify`'s figures)."""

    id: str = Field(description="The verification's id in the station's history.")
    date: datetime = Field(description="When it was made (UTC).")
    reference_mm: dict[str, float] = Field(description="The reference part's width, depth and height.")
    tolerance_mm: float | None = Field(
        description="T of +-T (the tolerance's full width is 2T); null if none.")
    photos: list[str] = Field(description="The placements' photos (file names), in order.")
    positions_mm: list[tuple[float, float]] = Field(description="Each placement's centre on the support.")
    yaws_deg: list[float] = Field(description="Each placement's yaw.")
    dimensions: dict[str, DimensionVerificationPublic] = Field(description="width, depth and height.")
    verified: bool = Field(description="The verdict (`rule`).")
    rule: str = Field(description="The verdict's rule in words.")
    grr_formula: str = Field(description="How %GRR is computed.")
    decided_by: list[str] = Field(description="The clauses failed (empty when verified).")


class VerificationList(BaseModel):
    verifications: list[VerificationPublic] = Field(description="Newest first.")


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
    verification: StationStatusPublic | None = Field(
        default=None, description="Its last verification with a reference part (POST "
        "/v1/stations/{id}/verifications, or prism station verify before upload), in short.")
    capability: CapabilityPublic | None = Field(
        default=None, description="Its scale over the support and the smallest part and tolerance it holds.")


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
    from prismcore.station import capability

    camera = station.camera
    calibration = {k: v for k, v in station.calibration.items() if k != "views_left_out"}
    return StationPublic(
        id=station_id, name=name, created_at=created_at, image_width=camera.image_width,
        image_height=camera.image_height, board=station.board.describe(),
        camera={"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                "dist": list(camera.dist)},
        calibration=calibration, plane_rms_px=station.plane.rms_px, plane_corners=station.plane.corners,
        camera_height_mm=round(-float(station.plane.camera_centre()[2]), 1),
        has_plate=station.plate_png is not None, size=size, verification=_status(station),
        capability=CapabilityPublic.model_validate(capability(station)))


def _status(station: Station) -> StationStatusPublic:
    from prismcore.station import verification_status

    found = verification_status(station.verification, moved=False)
    return StationStatusPublic.model_validate({k: found[k] for k in StationStatusPublic.model_fields})


def verification_prefix(tenant: str, station_id: str) -> str:
    return f"{_folder(tenant, station_id)}/verifications/"


def put_verification(objects: ObjectStore, tenant: str, station_id: str,
                     verification: VerificationPublic) -> None:
    """Keep a verification in the station's history (named by its date, then the moment it was
    stored: two made within one second, the date's resolution, are still listed in order)."""
    name = f"{verification.date:%Y%m%dT%H%M%S}-{time.time_ns():020d}-{verification.id}.json"
    key = verification_prefix(tenant, station_id) + name
    objects.put_bytes(key, verification.model_dump_json(indent=2).encode(), "application/json")


def list_verifications(objects: ObjectStore, tenant: str, station_id: str) -> list[VerificationPublic]:
    """The station's verifications, newest first."""
    found = []
    for key in sorted(objects.list_keys(verification_prefix(tenant, station_id)), reverse=True):
        if (doc := objects.get_json(key)) is not None:
            found.append(VerificationPublic.model_validate(doc))
    return found


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
    history = objects.list_keys(verification_prefix(tenant, station_id))
    if history:
        objects.delete_keys(history)
    return True

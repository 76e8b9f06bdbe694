"""/v1/stations: a tenant's stations (a camera calibrated to the support parts stand on), named
by job items as ``"station": ID`` so that a photo is measured with no points and no scale.

``POST /v1/stations`` takes a station.json (`prism station calibrate`'s output, validated by
`prismcore.station.Station`); GET one (its summary, without the plate), GET its station.json
(the plate included), list them, DELETE one. Another tenant's station answers 404, as an
unknown one does. Storage: `prism_common.stations` (the object store alone).
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Annotated, Any
from uuid import uuid4

import anyio
from fastapi import APIRouter, Query, Request, Response, status
from fastapi.exceptions import RequestValidationError
from prism_common.stations import (
    StationList,
    StationPublic,
    delete_station,
    get_summary,
    list_summaries,
    put_station,
    station_key,
    station_summary,
)
from pydantic import ValidationError

from ..deps import ObjectsDep, TenantDep
from ..problems import Problem

if TYPE_CHECKING:
    from prismcore.station import Station

router = APIRouter(prefix="/stations", tags=["stations"])

# The body is read by hand (its model imports the engine lazily), so its shape is declared here.
_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {"application/json": {
    "schema": {"type": "object", "description": "station.json, as `prism station calibrate` writes it: "
               "version, board, camera, plane, calibration, plate_png (base64 PNG of the empty support)."}}}}}


def _not_found(station_id: str) -> Problem:
    return Problem("not-found", f"no station {station_id[:64]!r}")


def _parse(raw: bytes) -> Station:
    """The body as a Station (prismcore.station imports OpenCV: only here)."""
    from prismcore.station import Station

    try:
        document = json.loads(raw)
    except ValueError as exc:
        raise Problem("bad-request", f"the body is not valid JSON ({exc})") from None
    try:
        return Station.model_validate(document)
    except ValidationError as exc:
        raise RequestValidationError([{**e, "loc": ("body", *e["loc"])} for e in exc.errors()],
                                     body=document) from None


@router.post("", status_code=status.HTTP_201_CREATED, response_model=StationPublic, openapi_extra=_BODY,
             responses={400: {"description": "Not JSON"},
                        415: {"description": "Not sent as application/json"},
                        422: {"description": "Not a station.json: `errors` points at the field"}})
async def create_station(request: Request, response: Response, tenant: TenantDep, objects: ObjectsDep,
                         name: Annotated[str | None, Query(max_length=200)] = None) -> StationPublic:
    """Store a station.json (`prism station calibrate`'s output) as one of your stations."""
    sent = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if sent != "application/json":
        detail = (f"the body is sent as Content-Type {sent!r}, not application/json: send "
                  "station.json with Content-Type: application/json") if sent else \
            "the body is sent without a Content-Type: send station.json as application/json"
        raise Problem("unsupported-media-type", detail, errors=[{"header": "Content-Type", "detail": detail}])
    raw = await request.body()
    station = await anyio.to_thread.run_sync(_parse, raw)
    # Stored as validated (a canonical document), so the worker reads what the API checked.
    data = station.model_dump_json().encode()
    station_id = uuid4().hex
    summary = station_summary(station, station_id, name=name, created_at=datetime.now(UTC), size=len(data))
    await anyio.to_thread.run_sync(put_station, objects, tenant, station_id, data, summary)
    response.headers["Location"] = f"/v1/stations/{station_id}"
    return summary


@router.get("", response_model=StationList)
def list_stations(tenant: TenantDep, objects: ObjectsDep) -> StationList:
    """Your stations, newest first (summaries: no plate)."""
    return StationList(stations=list_summaries(objects, tenant))


@router.get("/{station_id}", response_model=StationPublic,
            responses={404: {"description": "No such station"}})
def get_station(station_id: str, tenant: TenantDep, objects: ObjectsDep) -> StationPublic:
    """The station's summary: board, camera, the plane's fit, whether a plate is stored."""
    found = get_summary(objects, tenant, station_id)
    if found is None:
        raise _not_found(station_id)
    return found


@router.get("/{station_id}/station.json", responses={
    200: {"description": "station.json, the plate included", "content": {"application/json": {}}},
    404: {"description": "No such station"}})
def get_station_document(station_id: str, tenant: TenantDep, objects: ObjectsDep) -> Response:
    """The whole station.json (the plate as base64 PNG included), as `prism scan --station` reads it."""
    if get_summary(objects, tenant, station_id) is None:
        raise _not_found(station_id)
    return Response(objects.get_bytes(station_key(tenant, station_id)), media_type="application/json")


@router.delete("/{station_id}", status_code=status.HTTP_204_NO_CONTENT,
               responses={404: {"description": "No such station"}})
def remove_station(station_id: str, tenant: TenantDep, objects: ObjectsDep) -> Response:
    """Delete the station; items already queued that name it fail ("no station ...")."""
    if not delete_station(objects, tenant, station_id):
        raise _not_found(station_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)

"""/v1/stations: a tenant's stations (a camera calibrated to the support parts stand on), named
by job items as ``"station": ID`` so that a photo is measured with no points and no scale.

``POST /v1/stations`` takes a station.json (`prism station calibrate`'s output, validated by
`prismcore.station.Station`), or the photos to calibrate one from as multipart/form-data (board
and plane, the calibration photos unless a camera is given, the plate), calibrated here by
`prismcore.station.calibrate_station` in a worker thread (a dozen photos take a second or two of
CPU; the answer is the stored station, so a client needs no second round trip); GET one (its
summary, without the plate), GET its station.json (the plate included), list them, DELETE one.
Another tenant's station answers 404, as an unknown one does. Storage: `prism_common.stations`
(the object store alone). The body has a cap of its own, PRISM_STATION_MAX_BYTES (256 MiB: a
dozen full-size PNGs pass the 16 MiB every other body is held to; `bodylimit`), and is read only
after the key is checked.
"""

from __future__ import annotations

import json
import math
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

from ..deps import ObjectsDep, SettingsDep, TenantDep
from ..problems import Problem
from ..upload_stream import printable_name

if TYPE_CHECKING:
    from prismcore.station import Station

router = APIRouter(prefix="/stations", tags=["stations"])

# The body is read by hand (its model imports the engine lazily), so its shape is declared here;
# the JSON one is the Station model's schema, put in when the document is built (`document_station`).
_MAX_PHOTOS = 40
_MAX_FIELDS = 8  # parts sent as plain fields (no filename), as Starlette counts them
_FILE = {"type": "string", "format": "binary"}
_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {
    "application/json": {"schema": {"$ref": "#/components/schemas/Station"}},
    "multipart/form-data": {"schema": {
        "type": "object", "required": ["board", "plane"], "additionalProperties": False,
        "maxProperties": 5, "description": (
            "The photos to calibrate a station from, as `prism station calibrate` takes them. Only "
            "the five fields below (any other is refused, 422), each once but `calibration` (up to "
            f"{_MAX_PHOTOS} photos); at most {_MAX_FIELDS} parts sent as plain fields rather than files "
            f"(without a filename), and {_MAX_PHOTOS + 4} files: more is refused (400)."),
        "properties": {
            "board": {**_FILE, "description": "board.json (prism board, or any ChArUco board or "
                      "chessboard described so)."},
            "plane": {**_FILE, "description": "The board flat on the support, camera in its working "
                      "position: the station's frame."},
            "calibration": {"type": "array", "items": _FILE, "maxItems": _MAX_PHOTOS,
                            "description": "The board in several poses (the camera's intrinsics and "
                            "lens), unless `camera` is given."},
            "camera": {**_FILE, "description": "camera.json (prism calibrate): known intrinsics."},
            "plate": {**_FILE, "description": "The empty support from the working position."}}}}}}}


def document_station(schema: dict[str, Any]) -> dict[str, Any]:
    """Put station.json's schema (the Station model's, as `prism station calibrate` writes it) into
    an OpenAPI document's components, where POST /v1/stations' JSON body refers to it. Called when
    the document is built: the model imports OpenCV, which the API loads only when it is needed."""
    from prismcore.station import Station

    components = schema.setdefault("components", {}).setdefault("schemas", {})
    station = Station.model_json_schema(ref_template="#/components/schemas/Station{model}")
    for name, sub in station.pop("$defs", {}).items():
        # titled as named: a generated client names its classes by title, and the engine's own
        # CameraModel (a job's camera) would otherwise be defined twice
        components[f"Station{name}"] = {**sub, "title": f"Station{name}"}
    station["description"] = ("station.json, as `prism station calibrate` writes it (the plate as "
                              "base64 PNG). The model's own checks apply beyond this schema (a board "
                              "and plane that agree, a plate that decodes): 422 at the field.")
    components["Station"] = station
    return schema


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


def _finite(value: Any) -> bool:
    """Every number in a dumped model is finite."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, list | tuple):
        return all(_finite(v) for v in value)
    return True


_limiters: dict[int, anyio.CapacityLimiter] = {}


def _calibrations(at_once: int) -> anyio.CapacityLimiter:
    """This process's limit on stations calibrated at once (taken without waiting only, so one
    limiter serves any event loop)."""
    return _limiters.setdefault(at_once, anyio.CapacityLimiter(at_once))


def _invalid(field: str, detail: str) -> Problem:
    return Problem("validation", f"{field}: {detail}", errors=[{"pointer": f"/{field}", "detail": detail}])


async def _calibrated(request: Request, max_pixels: int, limiter: anyio.CapacityLimiter) -> Station:
    """The station the multipart photos calibrate (InputError's reason as a 422 at its field), one
    of `limiter`'s calibrations at a time (503 at capacity)."""
    form = await request.form(max_files=_MAX_PHOTOS + 4, max_fields=_MAX_FIELDS)
    try:
        files: dict[str, list[tuple[str, bytes]]] = {}
        for field, value in form.multi_items():
            if field not in ("board", "plane", "calibration", "camera", "plate"):
                raise _invalid(field, "not a field of a station's calibration (board, plane, calibration, "
                               "camera, plate)")
            if isinstance(value, str):
                files.setdefault(field, []).append((field, value.encode()))
            else:
                files.setdefault(field, []).append((value.filename or field, await value.read()))
    finally:
        await form.close()
    for field in ("board", "plane"):
        if field not in files:
            raise _invalid(field, f"missing: give {field}")
    for field in ("board", "plane", "camera", "plate"):
        if len(files.get(field, [])) > 1:
            raise _invalid(field, f"given {len(files[field])} times: give one")
    if "camera" not in files and not files.get("calibration"):
        raise _invalid("calibration", "give photos of the board in several poses, or a camera (camera.json)")
    try:
        limiter.acquire_nowait()
    except anyio.WouldBlock:
        # Refused rather than queued: each waiting request would hold its photos (up to
        # PRISM_STATION_MAX_BYTES) while the API's threads are taken by calibrations.
        raise Problem("at-capacity", f"{int(limiter.total_tokens)} stations are being calibrated by this "
                      "API process (PRISM_STATION_CALIBRATIONS_AT_ONCE); no station was created: send "
                      "it again shortly", headers={"Retry-After": "5"}) from None
    try:
        return await anyio.to_thread.run_sync(_calibrate, files, max_pixels)
    finally:
        limiter.release()


def _calibrate(files: dict[str, list[tuple[str, bytes]]], max_pixels: int) -> Station:
    from prismcore import InputError
    from prismcore.camera import CameraModel
    from prismcore.io import load_image
    from prismcore.station import BoardSpec, calibrate_station

    def model(field: str, cls: type[BoardSpec] | type[CameraModel]) -> Any:
        text = files[field][0][1]
        try:
            return cls.model_validate_json(text)
        except ValidationError as exc:
            first = exc.errors()[0]
            where = "/".join(str(p) for p in first["loc"])
            raise Problem("validation", f"{field}: {first['msg']}", errors=[
                {"pointer": f"/{field}" + (f"/{where}" if where else ""),
                 "detail": str(first["msg"]).removeprefix("Value error, ")}]) from None

    def photo(field: str, k: int = 0) -> Any:
        name, data = files[field][k]
        try:
            return load_image(data, max_pixels=max_pixels, name=name)
        except InputError as exc:
            raise _invalid(field if field != "calibration" else f"calibration/{k}", str(exc)) from None

    board = model("board", BoardSpec)
    camera = model("camera", CameraModel) if "camera" in files else None
    plane_name = files["plane"][0][0]
    try:
        return calibrate_station(
            board, photo("plane"),
            [(files["calibration"][k][0], photo("calibration", k))
             for k in range(len(files.get("calibration", [])))],
            camera=camera, plate=photo("plate") if "plate" in files else None, plane_name=plane_name)
    except InputError as exc:
        text = str(exc)
        field = "plane" if text.startswith(plane_name) else "plate" if "plate" in text else "calibration"
        raise _invalid(field, text) from None


@router.post("", status_code=status.HTTP_201_CREATED, response_model=StationPublic, openapi_extra=_BODY,
             responses={400: {"description": f"Not JSON, or a multipart body of more than {_MAX_FIELDS} "
                                             f"plain fields or {_MAX_PHOTOS + 4} files"},
                        415: {"description": "Sent as neither application/json nor multipart/form-data"},
                        422: {"description": "Not a station.json, or photos and files that calibrate no "
                                             "station: `errors` points at the field"}})
async def create_station(request: Request, response: Response, tenant: TenantDep, objects: ObjectsDep,
                         settings: SettingsDep,
                         name: Annotated[str | None, Query(max_length=200, description=(
                             "Your own name for it, kept as upload names are: control characters "
                             "(NUL, CR, LF...) and invisible format characters (right-to-left "
                             "overrides and isolates...) dropped, spaces at its ends stripped"))] = None,
                         ) -> StationPublic:
    """Store a station: a station.json (`prism station calibrate`'s output, schema `Station`), or
    one calibrated here from its photos (multipart: board, plane, calibration..., camera, plate;
    no other field, at most 40 calibration photos, at most 8 parts sent as plain fields rather
    than files and 44 files in all, more refused with 400)."""
    name = (printable_name(name) or None) if name else None  # all of it unprintable: no name
    sent = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if sent == "multipart/form-data":
        limiter = _calibrations(settings.station_calibrations_at_once)
        station = await _calibrated(request, settings.max_pixels, limiter)
    elif sent == "application/json":
        station = await anyio.to_thread.run_sync(_parse, await request.body())
    else:
        detail = (f"the body is sent as Content-Type {sent!r}: send station.json as application/json, "
                  "or the photos to calibrate as multipart/form-data") if sent else \
            "the body is sent without a Content-Type: send station.json as application/json"
        raise Problem("unsupported-media-type", detail, errors=[{"header": "Content-Type", "detail": detail}])
    # Stored as validated (a canonical document), so the worker reads what the API checked.
    data = station.model_dump_json().encode()
    station_id = uuid4().hex
    summary = station_summary(station, station_id, name=name, created_at=datetime.now(UTC), size=len(data))
    if not _finite(summary.model_dump(mode="python")):
        # A pose or camera the model takes whose figures overflow (a plane 1e300 mm away): the
        # summary could not be answered as JSON numbers, so the station is refused, not kept.
        raise _invalid("plane", "the camera's pose and intrinsics give no finite position of the camera "
                       "over the support")
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

"""/v1/stations/{id}/verifications: a station verified with a reference part of known size, and
its history.

``POST`` takes the reference part's photos (multipart ``photo``, one per placement, at least 5),
its size ``reference`` "W,D,H" (mm, width >= depth, then height) and an optional ``tolerance`` (T of
+-T, mm); each photo is measured on the station and the placements verified in a worker thread by
`prismcore.station.certify.verify_station`, as `prism station verify` does (a few photos take a
second or two of CPU: the answer is the verification, so a client needs no second round trip).
The verification is kept in the station's history, and stored in its station.json and summary, so
every later measurement on the station states it. Verified or not, the answer is 201 with the
figures and the verdict; photos the station cannot measure, too few placements or placements not
spread over the support are 422 with the reason, nothing stored. ``GET`` lists the history,
newest first. One verification or calibration at a time per `PRISM_STATION_CALIBRATIONS_AT_ONCE`
(the same limiter as POST /v1/stations' calibrations; 503 with Retry-After past it).
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any
from uuid import uuid4

import anyio
from fastapi import APIRouter, Request, Response, status
from prism_common.stations import (
    StationPublic,
    VerificationList,
    VerificationPublic,
    get_summary,
    list_verifications,
    put_station,
    put_verification,
    station_key,
    station_summary,
)

from ..deps import ObjectsDep, SettingsDep, TenantDep
from ..problems import Problem
from .stations import _calibrations, _invalid, _not_found

router = APIRouter(prefix="/stations", tags=["stations"])

_MAX_PHOTOS = 40
_MAX_FIELDS = 4  # reference and tolerance, sent as plain fields
_FILE = {"type": "string", "format": "binary"}
_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {
    "multipart/form-data": {"schema": {
        "type": "object", "required": ["photo", "reference"], "additionalProperties": False,
        "maxProperties": 3, "description": (
            "The reference part's photos and its size, as `prism station verify` takes them. Only "
            f"the three fields below (any other is refused, 422); `photo` up to {_MAX_PHOTOS} times, "
            f"at least 5; at most {_MAX_FIELDS} parts sent as plain fields (400 past it)."),
        "properties": {
            "photo": {"type": "array", "items": _FILE, "minItems": 1, "maxItems": _MAX_PHOTOS,
                      "description": "The reference part on the support, one photo per placement: at "
                      "least 5, at different positions and yaws across the support."},
            "reference": {"type": "string", "maxLength": 100,
                          "description": "Its true size W,D,H in mm (width >= depth, then height), e.g. "
                          "70,45,30."},
            "tolerance": {"type": "string", "maxLength": 100,
                          "description": "T of +-T, mm (> 0): %GRR is judged against 2T, and a bias "
                          "under 10 % of 2T accepted. Without it the bias must not be significant."}}}}}}}


def _tolerance(text: str | None) -> float | None:
    if text is None or not text.strip():
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise _invalid("tolerance", f"{text[:100]!r}: expected T > 0 (mm, for +-T)")
    return value


async def _form(request: Request) -> tuple[list[tuple[str, bytes]], str, float | None]:
    form = await request.form(max_files=_MAX_PHOTOS, max_fields=_MAX_FIELDS)
    photos: list[tuple[str, bytes]] = []
    plain: dict[str, list[str]] = {}
    try:
        for field, value in form.multi_items():
            if field not in ("photo", "reference", "tolerance"):
                raise _invalid(field[:100], "not a field of a verification (photo, reference, tolerance)")
            if field == "photo":
                if isinstance(value, str):
                    raise _invalid("photo", "send each photo as a file")
                photos.append((value.filename or f"photo {len(photos) + 1}", await value.read()))
            else:
                plain.setdefault(field, []).append(value if isinstance(value, str)
                                                   else (await value.read()).decode("utf-8", "replace"))
    finally:
        await form.close()
    for field, values in plain.items():
        if len(values) > 1:
            raise _invalid(field, f"given {len(values)} times: give one")
    if "reference" not in plain:
        raise _invalid("reference", "missing: give the reference part's size W,D,H in mm")
    if not photos:
        raise _invalid("photo", "missing: give the reference part's photos, one per placement")
    return photos, plain["reference"][0], _tolerance(plain.get("tolerance", [None])[0])


def _verify(document: bytes, photos: list[tuple[str, bytes]], reference: str, tolerance: float | None,
            max_pixels: int) -> tuple[Any, Any]:
    """(the station with its new verification, the verification): the engine, in a thread."""
    from prismcore import InputError
    from prismcore.io import load_image
    from prismcore.station import Station, parse_reference, verify_station

    try:
        size = parse_reference(reference, "reference")
    except InputError as exc:
        raise _invalid("reference", str(exc)) from None
    station = Station.model_validate_json(document)
    decoded = []
    for k, (name, data) in enumerate(photos):
        try:
            decoded.append((name, load_image(data, max_pixels=max_pixels, name=name)))
        except InputError as exc:
            raise _invalid(f"photo/{k}", str(exc)) from None
    try:
        done = verify_station(station, decoded, size, tolerance, datetime.now(UTC).replace(microsecond=0))
    except InputError as exc:
        text = str(exc)
        at = next((k for k, (name, _) in enumerate(photos) if text.startswith(f"{name}: ")), None)
        raise _invalid("photo" if at is None else f"photo/{at}", text) from None
    return station.model_copy(update={"verification": done}), done


@router.post("/{station_id}/verifications", status_code=status.HTTP_201_CREATED,
             response_model=VerificationPublic, openapi_extra=_BODY,
             responses={400: {"description": f"A multipart body of more than {_MAX_FIELDS} plain fields or "
                                             f"{_MAX_PHOTOS} files"},
                        404: {"description": "No such station"},
                        415: {"description": "Not sent as multipart/form-data"},
                        422: {"description": "A bad reference or tolerance, a photo the station cannot "
                                             "measure, fewer than 5 placements, placements not spread "
                                             "over the support, or a placement showing the camera one "
                                             "side of the part only: `errors` points at the field"}})
async def create_verification(station_id: str, request: Request, response: Response, tenant: TenantDep,
                              objects: ObjectsDep, settings: SettingsDep) -> VerificationPublic:
    """Verify the station with a reference part: its photos in several placements (multipart
    `photo`, at least 5), its size `reference` W,D,H mm and optionally `tolerance` T. Answers the
    verification (bias, repeatability, 3-sigma checks, %GRR and the verdict), verified or not,
    and stores it: the station's summary and every later measurement on it state it."""
    summary = get_summary(objects, tenant, station_id)
    if summary is None:
        raise _not_found(station_id)
    sent = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if sent != "multipart/form-data":
        detail = "send the reference part's photos, its reference and tolerance as multipart/form-data"
        raise Problem("unsupported-media-type", detail, errors=[{"header": "Content-Type", "detail": detail}])
    photos, reference, tolerance = await _form(request)
    limiter = _calibrations(settings.station_calibrations_at_once)
    try:
        limiter.acquire_nowait()
    except anyio.WouldBlock:
        raise Problem("at-capacity", f"{int(limiter.total_tokens)} stations are being calibrated or verified "
                      "by this API process (PRISM_STATION_CALIBRATIONS_AT_ONCE); nothing was stored: send "
                      "it again shortly", headers={"Retry-After": "5"}) from None
    try:
        document = await anyio.to_thread.run_sync(objects.get_bytes, station_key(tenant, station_id))
        station, done = await anyio.to_thread.run_sync(_verify, document, photos, reference, tolerance,
                                                       settings.max_pixels)
    finally:
        limiter.release()
    verification = VerificationPublic.model_validate({**done.model_dump(mode="json"), "id": uuid4().hex})
    data = station.model_dump_json().encode()
    updated: StationPublic = station_summary(station, station_id, name=summary.name,
                                             created_at=summary.created_at, size=len(data))
    await anyio.to_thread.run_sync(put_verification, objects, tenant, station_id, verification)
    await anyio.to_thread.run_sync(put_station, objects, tenant, station_id, data, updated)
    response.headers["Location"] = f"/v1/stations/{station_id}/verifications"
    return verification


@router.get("/{station_id}/verifications", response_model=VerificationList,
            responses={404: {"description": "No such station"}})
def list_station_verifications(station_id: str, tenant: TenantDep, objects: ObjectsDep) -> VerificationList:
    """The station's verifications with a reference part, newest first."""
    if get_summary(objects, tenant, station_id) is None:
        raise _not_found(station_id)
    return VerificationList(verifications=list_verifications(objects, tenant, station_id))

"""/v1/jobs: submit a batch of scans, follow it, list and cancel jobs.

A job is only ever visible to its tenant: another tenant's id is answered like an unknown one.
"""

from __future__ import annotations

import base64
import binascii
import logging
import math
import re
from datetime import UTC, datetime
from typing import Annotated
from urllib.parse import unquote, urlsplit
from uuid import uuid4

from fastapi import APIRouter, Depends, Header, HTTPException, Query, Request, Response, status
from fastapi.exceptions import RequestValidationError
from kombu.exceptions import OperationalError
from prism_common import public
from prism_common.queue import TASK_RUN_JOB
from prism_common.records import ENDED_STATES, ItemRecord, JobRecord, State
from prism_common.references import parse_reference
from prism_common.settings import Settings
from prism_common.stations import get_summary
from prism_common.store import IdempotencyConflictError, JobStore

from prismcore.spec import METRIC_FORMATS, OutputFormat, ScanSpec

from ..backpressure import check_queue_depth
from ..deps import CeleryDep, ObjectsDep, PresignerDep, RedisDep, SettingsDep, StoreDep, TenantDep
from ..presign import Presigner
from ..schemas import JobCreate, JobList, JobPublic
from ..validation import KINDS, check_job

router = APIRouter(prefix="/jobs", tags=["jobs"])
log = logging.getLogger(__name__)

_JOB_ID = re.compile(r"^[0-9a-f]{32}$")


def to_public(job: JobRecord, presigner: Presigner, item_count: int | None = None) -> JobPublic:
    return public.to_public(job, presigner.url, item_count)


def _not_found(job_id: str) -> HTTPException:
    return HTTPException(status.HTTP_404_NOT_FOUND, f"no job {job_id[:64]!r}")


def own_job(store: JobStore, job_id: str, tenant: str) -> JobRecord:
    job = store.get(job_id) if _JOB_ID.match(job_id) else None
    if job is None or job.tenant != tenant:
        raise _not_found(job_id)
    return job


def own_page(store: JobStore, job_id: str, tenant: str, offset: int, limit: int) -> tuple[JobRecord, int]:
    """The job with only its items offset..offset+limit-1, and its number of items (404 as own_job)."""
    page = store.get_page(job_id, offset, limit) if _JOB_ID.match(job_id) else None
    if page is None or page[0].tenant != tenant:
        raise _not_found(job_id)
    return page


async def _raw_body(request: Request) -> bytes:
    return await request.body()  # already read for the JobCreate parameter: served from memory


@router.post("", status_code=status.HTTP_202_ACCEPTED, response_model=JobPublic,
             responses={409: {"description": "Idempotency-Key reused with another body"}})
def create_job(job_in: JobCreate, response: Response, tenant: TenantDep, settings: SettingsDep,
               store: StoreDep, presigner: PresignerDep, celery: CeleryDep, client: RedisDep,
               objects: ObjectsDep, body: Annotated[bytes, Depends(_raw_body)],
               idempotency_key: Annotated[str | None, Header(max_length=200)] = None) -> JobPublic:
    """Queue a batch of scans. Repeating a request with the same Idempotency-Key returns its job."""
    try:
        # First: a client retrying a job that was taken gets it back even while the queue is full.
        if idempotency_key and (job := store.find_idempotent(tenant, idempotency_key, body)):
            response.headers["Location"] = _location(settings.public_base_url, job.id)
            return to_public(job, presigner)
    except IdempotencyConflictError as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    uploads = check_job(job_in, settings, store, tenant, raw=body,
                        stations=lambda station_id: get_summary(objects, tenant, station_id))
    check_queue_depth(client, settings)
    items = [_record(i, item, settings, uploads) for i, item in enumerate(job_in.items)]
    record = JobRecord(id=uuid4().hex, tenant=tenant, items=items, created_at=datetime.now(UTC),
                       client_reference=job_in.client_reference, webhook_url=job_in.webhook_url)
    try:
        job, created = store.create(record, idempotency_key=idempotency_key, body=body)
    except IdempotencyConflictError as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    if created:
        store.touch_uploads(set(uploads))  # they expire counting from their last job, not their upload
        try:
            # ignore_result: the API never reads run_job's result; without it Celery's Redis
            # backend subscribes this process to every task's result channel, for good.
            celery.send_task(TASK_RUN_JOB, args=[job.id], ignore_result=True)
        except OperationalError as exc:
            # Failed rather than left queued forever: a retry with the key would not re-send it.
            log.error("job %s could not be queued: %s", job.id, exc)
            store.transition(job.id, State.failed, error="the job could not be queued")
            raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE,
                                f"the job queue is unavailable; job {job.id} was not started") from None
    response.headers["Location"] = _location(settings.public_base_url, job.id)
    return to_public(job, presigner)


def _record(index: int, spec: ScanSpec, settings: Settings, uploads: dict[str, str | None]) -> ItemRecord:
    """The item as stored: its spec (the service's pixel cap, formats and spacing applied) and the
    name its image was sent under (an upload's; an https URL's last segment)."""
    update = {"max_pixels": min(spec.max_pixels, settings.max_pixels),
              "formats": _formats(spec, settings.default_formats),
              "spacing_mm": _spacing(spec, settings.default_spacing_mm)}
    return ItemRecord(index=index, spec=spec.model_copy(update=update), file_name=_file_name(spec, uploads))


def _file_name(item: ScanSpec, uploads: dict[str, str | None]) -> str | None:
    """The name the item's (front) image was sent under: its upload's, or an https URL's last path
    segment; None for an object-store key (`input` names it)."""
    ref = parse_reference(item.image)  # checked at submit: a reference of a kind the service reads
    if ref.kind == "upload":
        return uploads.get(ref.upload_id)
    if ref.kind == "https":
        return unquote(urlsplit(item.image).path.rsplit("/", 1)[-1]) or None
    return None


def _formats(spec: ScanSpec, defaults: list[OutputFormat]) -> list[OutputFormat]:
    """The item's formats: its own, else the operator's defaults it can have (the format table's
    METRIC_FORMATS need a scale), else csv and ply. A joint fit (views, or a video's
    frames fitted as one box) writes no cloud and keeps the spec's own (the spec allows no other)."""
    if "formats" in spec.model_fields_set or KINDS[spec.kind].own_formats:
        return spec.formats
    scaled = spec.scale is not None or spec.station is not None  # a station's plane gives the mm
    usable = [f for f in defaults if scaled or f not in METRIC_FORMATS]
    return usable or ["csv", "ply"]


def _spacing(spec: ScanSpec, default: float | None) -> float | None:
    """The item's cloud spacing (mm): its own (an explicit null: one point per pixel), else the
    operator's default for an item in mm (a scale, or a station's plane), else none. A joint fit
    makes no cloud and keeps the spec's own (the spec allows no other)."""
    if "spacing_mm" in spec.model_fields_set or KINDS[spec.kind].own_formats:
        return spec.spacing_mm
    return default if spec.scale is not None or spec.station is not None else None


def _location(base_url: str | None, job_id: str) -> str:
    return f"{(base_url or '').rstrip('/')}/v1/jobs/{job_id}"


def _encode_cursor(score: float | None) -> str | None:
    # Opaque to clients: the store's position (a creation time in us), which may change shape.
    return base64.urlsafe_b64encode(repr(score).encode()).decode() if score is not None else None


def _decode_cursor(cursor: str | None) -> float | None:
    if cursor is None:
        return None
    try:
        value = float(base64.urlsafe_b64decode(cursor.encode()).decode())
    except (ValueError, binascii.Error, UnicodeError):
        value = math.nan
    if not math.isfinite(value):
        raise RequestValidationError([{"type": "value_error", "loc": ("query", "cursor"),
                                       "msg": f"cursor {cursor!r} is not one this API gave out"}])
    return value


@router.get("", response_model=JobList)
def list_jobs(tenant: TenantDep, store: StoreDep, presigner: PresignerDep,
              state: State | None = None, limit: Annotated[int, Query(ge=1, le=200)] = 50,
              cursor: Annotated[str | None, Query(max_length=100)] = None,
              items: bool = True) -> JobList:
    """Your jobs, newest first; follow `next_cursor` for the next page. `items=false` leaves
    the items out (each job still says its `item_count`): a listing of big jobs stays small."""
    jobs, next_score = store.list(tenant, state=state, limit=limit, cursor=_decode_cursor(cursor),
                                  items=items)
    return JobList(jobs=[to_public(j, presigner, n) for j, n in jobs],
                   next_cursor=_encode_cursor(next_score))


@router.get("/{job_id}", response_model=JobPublic, responses={404: {"description": "No such job"}})
def get_job(job_id: str, tenant: TenantDep, store: StoreDep, presigner: PresignerDep,
            item_offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
            item_limit: Annotated[int | None, Query(ge=0, le=10_000)] = None) -> JobPublic:
    """The job, with all its items, or the page of them that item_offset and item_limit name
    (item_limit=0: none, for a cheap poll of a large job's state and progress)."""
    if item_offset == 0 and item_limit is None:
        return to_public(own_job(store, job_id, tenant), presigner)
    job, n_items = own_page(store, job_id, tenant, item_offset,
                            10**9 if item_limit is None else item_limit)
    return to_public(job, presigner, n_items)


@router.post("/{job_id}/cancel", response_model=JobPublic,
             responses={404: {"description": "No such job"}, 409: {"description": "Already over"}})
def cancel_job(job_id: str, tenant: TenantDep, store: StoreDep, presigner: PresignerDep) -> JobPublic:
    """Stop a queued or running job; cancelling a cancelled job again changes nothing."""
    own_job(store, job_id, tenant)
    if not store.transition(job_id, State.cancelled):
        state = store.state(job_id)
        if state in ENDED_STATES:
            raise HTTPException(status.HTTP_409_CONFLICT, f"job is already {state.value}")
    return to_public(own_job(store, job_id, tenant), presigner)

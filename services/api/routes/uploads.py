"""POST /v1/uploads: a photo or video streamed into object storage, to be named by jobs as upload:ID.

Each upload is probed as it is stored (`prism_api.probe`): a file that is neither a photo the
engine reads nor a video is refused (415) and deleted, and so is a photo cut short (422,
damaged-file); what the others are (format, pixel size, a video's frames) is recorded with the
upload, so a job naming it is checked at submit.
"""

from __future__ import annotations

import tempfile
from functools import partial
from typing import IO, Any, BinaryIO, cast
from uuid import uuid4

import anyio
from fastapi import APIRouter, HTTPException, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from prism_common.settings import Settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore
from prism_common.upload_keys import upload_key

from ..deps import ObjectsDep, SettingsDep, StoreDep, TenantDep
from ..probe import ImageEnd, Unsupported, is_video_head, probe_image_head, probe_video_file
from ..problems import Problem
from ..schemas import UploadProbe, UploadPublic
from ..upload_stream import HEAD_KEEP, MULTIPART_OVERHEAD, MultipartFile

router = APIRouter(prefix="/uploads", tags=["uploads"])

# The body is read by hand (streamed, size-limited), so its shape is declared for the docs here.
_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {"multipart/form-data": {
    "schema": {"type": "object", "required": ["file"],
               "properties": {"file": {"type": "string", "format": "binary"}}}}}}}
_SUPPORTED = "a photo (BMP, PNG, JPEG, TIFF, WebP) or a video (AVI, MP4, MOV, MKV)"


def _spool_videos(first: bytes) -> IO[bytes] | None:
    # A video is probed by OpenCV, which reads files only: a local copy is kept while it is stored.
    return tempfile.NamedTemporaryFile(prefix="prism-upload-", suffix=".video") if is_video_head(first) \
        else None


class Truncated(Exception):  # noqa: N818 - a finding, not a failure of the code
    """A photo whose header is whole but whose data stops short of its end."""


def _watch_photos(first: bytes, max_pixels: int) -> ImageEnd | None:
    # A PNG over the pixel limit is not inflated here: the worker refuses it as too large.
    return None if is_video_head(first) else ImageEnd(first, max_pixels=max_pixels)


_limiters: dict[int, anyio.CapacityLimiter] = {}


def _taken(at_once: int) -> anyio.CapacityLimiter | None:
    """One of this process's `at_once` uploads taken (None when there is no cap), or 503.

    Refused rather than queued: a waiting upload holds its connection and what has come of its
    body, so queued ones grow the API's memory with whatever clients send at once. Taken without
    waiting only, so one limiter serves any event loop. The connection is kept (no
    `Connection: close`, unlike a 401 or 413: those refuse a client that should not send again):
    uvicorn drops the rest of the body as it comes rather than holding it, whereas a socket closed
    with data unread is reset, and a client still sending may see the reset, not this answer."""
    if at_once <= 0:
        return None
    limiter = _limiters.setdefault(at_once, anyio.CapacityLimiter(at_once))
    try:
        limiter.acquire_nowait()
    except anyio.WouldBlock:
        raise Problem("at-capacity", f"{at_once} uploads are being taken by this API process "
                      "(PRISM_UPLOADS_AT_ONCE); nothing was stored: send it again shortly",
                      headers={"Retry-After": "1"}) from None
    return limiter


def _probe(upload: MultipartFile) -> dict[str, Any]:
    """What the stored file is (in a worker thread: OpenCV may decode a whole video)."""
    head = bytes(upload.head)
    if upload.spool is not None:
        upload.spool.flush()
        return probe_video_file(upload.spool.name, head=head, name=upload.name)
    probe = probe_image_head(head, complete=upload.size <= HEAD_KEEP, name=upload.name)
    # After the probe: a file that is no photo at all is Unsupported, whatever its end.
    cut = upload.watch.problem(upload.name) if isinstance(upload.watch, ImageEnd) else None
    if cut is not None:
        raise Truncated(cut)
    return probe


@router.post("", status_code=status.HTTP_201_CREATED, response_model=UploadPublic,
             openapi_extra=_BODY, responses={
                 200: {"description": "The same content was uploaded before: that upload",
                       "model": UploadPublic},
                 413: {"description": "Larger than the upload limit"},
                 415: {"description": "Neither a photo nor a video (an empty file, text, a PDF...): "
                       "`detail` and `detected_type` name what it is"},
                 422: {"description": "No non-empty multipart `file` (validation), or a photo cut "
                       "short (damaged-file: `detail` says so)",
                       "x-problem-types": ["validation", "damaged-file"]},
                 503: {"description": "The API process is taking as many uploads as it may at once "
                       "(at-capacity, PRISM_UPLOADS_AT_ONCE: send it again after `Retry-After`), or "
                       "a store is down"}})

async def create_upload(request: Request, response: Response, tenant: TenantDep, settings: SettingsDep,
                        store: StoreDep, objects: ObjectsDep) -> UploadPublic:
    """Stream the multipart field `file` into object storage; refused past the size limit (413),
    when it is neither a photo nor a video (415) or is a photo cut short (422), and while this API
    process takes PRISM_UPLOADS_AT_ONCE others (503, Retry-After). The answer says what the file is."""
    limit = settings.upload_max_bytes
    length = request.headers.get("content-length", "")
    if length.isdigit() and int(length) > limit + MULTIPART_OVERHEAD:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE,  # refused unread
                            f"the upload is larger than {limit} bytes", headers={"Connection": "close"})
    taken = _taken(settings.uploads_at_once)
    try:
        return await _stored(request, response, tenant, settings, store, objects)
    finally:
        if taken is not None:
            taken.release()


async def _stored(request: Request, response: Response, tenant: str, settings: Settings,
                  store: JobStore, objects: ObjectStore) -> UploadPublic:
    """The upload read off the request, stored, probed and recorded (or found stored before)."""
    limit = settings.upload_max_bytes
    upload = MultipartFile(request, "file", limit, spool_when=_spool_videos,
                           watch_when=partial(_watch_photos, max_pixels=settings.max_pixels))
    upload_id = uuid4().hex
    key = upload_key(tenant, upload_id)
    try:
        try:
            # A file object to boto3, which only read()s it (it has no seek: a multipart upload).
            await anyio.to_thread.run_sync(objects.put_stream, key, cast(BinaryIO, upload))
        except Exception:
            if upload.failure is not None:  # our own refusal, possibly wrapped by boto3
                raise upload.failure from None
            raise
        finally:
            await upload.aclose()
        try:
            probe = await anyio.to_thread.run_sync(_probe, upload)
        except Unsupported as exc:
            await anyio.to_thread.run_sync(objects.delete_keys, [key])
            raise Problem("unsupported-media-type", f"{upload.name!r} is {exc.detected}, not {_SUPPORTED}",
                          detected_type=exc.detected) from None
        except Truncated as exc:
            await anyio.to_thread.run_sync(objects.delete_keys, [key])
            raise Problem("damaged-file", str(exc), truncated=True) from None
    finally:
        if upload.spool is not None:
            upload.spool.close()  # deletes the local copy
    digest = upload.sha256.hexdigest()
    existing = await run_in_threadpool(store.find_upload, tenant, digest, upload.name)
    if existing is not None and await anyio.to_thread.run_sync(objects.exists, existing[1]["key"]):
        # The tenant has this very file (content and name) stored: one copy is kept, its
        # lifetime renewed.
        found_id, record = existing
        await anyio.to_thread.run_sync(objects.delete_keys, [key])
        await run_in_threadpool(store.touch_uploads, {found_id})
        response.status_code = status.HTTP_200_OK
        return UploadPublic(id=found_id, reference=f"upload:{found_id}", size=int(record["size"]),
                            name=record.get("name", upload.name), sha256=digest,
                            probe=UploadProbe(**probe))
    await run_in_threadpool(store.put_upload, upload_id, tenant=tenant, key=key, size=upload.size,
                            name=upload.name, probe=probe, sha256=digest)
    return UploadPublic(id=upload_id, reference=f"upload:{upload_id}", size=upload.size,
                        name=upload.name, probe=UploadProbe(**probe), sha256=digest)

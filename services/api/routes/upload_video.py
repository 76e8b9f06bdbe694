"""An uploaded video's facts and frames, for marking points on a frame before a job is sent.

``GET /v1/uploads/{id}/video`` and ``GET /v1/uploads/{id}/frames/{n}.png``. The API decodes
nothing (no numpy or OpenCV here): it sends `prism.extract_frame` to a worker, answers 202
with Retry-After until the worker has written what was asked, then serves it from the bucket.
A frame is the very PNG the worker's decoder makes, so what a person marks is what is measured.
Another tenant's upload answers 404, like an unknown one.
"""

from __future__ import annotations

from typing import Annotated, Any

from celery import Celery
from fastapi import APIRouter, HTTPException, Path, status
from fastapi.responses import JSONResponse, StreamingResponse
from kombu.exceptions import OperationalError
from prism_common.queue import TASK_EXTRACT_FRAME
from prism_common.store import JobStore
from prism_common.upload_keys import frame_error_key, frame_png_key, video_info_key

from ..deps import CeleryDep, ObjectsDep, StoreDep, TenantDep
from ..relay import relay_object
from ..schemas import VideoPublic

router = APIRouter(prefix="/uploads", tags=["uploads"])

RETRY_AFTER_S = 1
CLAIM_TTL_S = 30  # a lost extraction is asked for again after this
_PENDING: dict[int | str, dict[str, Any]] = {
    202: {"description": "The worker is decoding it: ask again after Retry-After seconds"}}
_PNG: dict[str, Any] = {"content": {"image/png": {}},
                        "description": "The frame, lossless, as the worker decodes it."}


def _own_upload(store: JobStore, upload_id: str, tenant: str) -> dict[str, str]:
    upload = store.get_upload(upload_id) if len(upload_id) <= 64 else None
    if upload is None or upload.get("tenant") != tenant:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no upload {upload_id[:64]!r}")
    return upload


def _refused(found: dict) -> HTTPException:
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, found["error"])


def ask_worker(claimed: bool, celery: Celery, task: str, args: list, doing: str) -> JSONResponse:
    """Send `task` when this poll `claimed` it (an expiring claim: once per CLAIM_TTL_S, however
    often the page polls) and answer 202: "the worker is `doing`; ask again"."""
    if claimed:
        try:
            celery.send_task(task, args=args, ignore_result=True)
        except OperationalError:
            raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE,
                                "the worker queue is unavailable; try again shortly") from None
    return JSONResponse({"detail": f"the worker is {doing}; ask again in {RETRY_AFTER_S} s"},
                        status_code=status.HTTP_202_ACCEPTED, headers={"Retry-After": str(RETRY_AFTER_S)})


def _pending(store: JobStore, celery: Celery, upload_id: str, frame: int, what: str) -> JSONResponse:
    """Ask a worker for the frame: 202."""
    return ask_worker(store.claim_extraction(upload_id, frame, CLAIM_TTL_S), celery, TASK_EXTRACT_FRAME,
                      [upload_id, frame], f"decoding {what}")


@router.get("/{upload_id}/video", response_model=VideoPublic,
            responses={**_PENDING, 404: {"description": "No such upload"},
                       422: {"description": "Not a video that decodes"}})
def get_video(upload_id: str, tenant: TenantDep, store: StoreDep, objects: ObjectsDep,
              celery: CeleryDep) -> VideoPublic | JSONResponse:
    """Frame count, frame rate, size and codec of an uploaded video (the first call starts
    decoding it, and its frame 0)."""
    upload = _own_upload(store, upload_id, tenant)
    info = objects.get_json(video_info_key(upload["tenant"], upload_id))
    if info is None:
        return _pending(store, celery, upload_id, 0, f"upload {upload_id}")
    if "error" in info:
        raise _refused(info)
    return VideoPublic(id=upload_id, **info)


@router.get("/{upload_id}/frames/{frame}.png", response_class=StreamingResponse, response_model=None,
            responses={200: _PNG, **_PENDING, 404: {"description": "No such upload or frame"},
                       422: {"description": "Not a video, or a frame that does not decode"}})
def get_frame(upload_id: str, frame: Annotated[int, Path(ge=0)], tenant: TenantDep, store: StoreDep,
              objects: ObjectsDep, celery: CeleryDep) -> StreamingResponse | JSONResponse:
    """Frame `frame` (0 = the first) of an uploaded video, as the worker decodes it."""
    upload = _own_upload(store, upload_id, tenant)
    owner = upload["tenant"]
    info = objects.get_json(video_info_key(owner, upload_id))
    if info is not None:
        if "error" in info:
            raise _refused(info)
        if frame >= info["frame_count"]:
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"no frame {frame}: upload {upload_id} has "
                                f"{info['frame_count']} frames (0-{info['frame_count'] - 1})")
    response = relay_object(objects, frame_png_key(owner, upload_id, frame), "image/png", max_age_s=3600)
    if response is not None:
        return response
    if (failed := objects.get_json(frame_error_key(owner, upload_id, frame))) is not None:
        raise _refused(failed)
    return _pending(store, celery, upload_id, frame, f"frame {frame} of upload {upload_id}")

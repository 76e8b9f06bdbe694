"""An item's (or a video frame's) display cloud, streamed through the API.

``GET /v1/jobs/{id}/items/{n}/preview.ply`` and ``.../items/{n}/frames/{f}/preview.ply``.
The web page draws the cloud with WebGL from its own origin, so these routes relay the
worker's decimated preview object (`relay`). Another tenant's job answers 404, like every job route.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, status
from fastapi.responses import StreamingResponse
from prism_common.records import ItemRecord
from prism_common.storage import ObjectStore

from ..deps import ObjectsDep, StoreDep, TenantDep
from ..relay import relay_object
from .jobs import own_job

__all__ = ["router"]

router = APIRouter(prefix="/jobs", tags=["jobs"])

_PLY = {"content": {"application/octet-stream": {}},
        "description": "Binary little-endian PLY: float32 x, y, z (mm) and uchar red, green, blue."}
_RESPONSES = {200: _PLY, 404: {"description": "No such job, item, frame or preview"}}
Index = Annotated[int, Path(ge=0)]


def _item(store, job_id: str, index: int, tenant: str) -> ItemRecord:
    job = own_job(store, job_id, tenant)
    if index >= len(job.items):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} has no item {index}")
    return job.items[index]


def _relay(objects: ObjectStore, key: str | None, what: str, noun: str, state: str) -> StreamingResponse:
    if key is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"{what} has no preview (the {noun} is {state})")
    response = relay_object(objects, key, "application/octet-stream", max_age_s=300)
    if response is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"the preview of {what} is gone")
    return response


@router.get("/{job_id}/items/{index}/preview.ply", response_class=StreamingResponse, responses=_RESPONSES)
def get_preview(job_id: str, index: Index, tenant: TenantDep, store: StoreDep,
                objects: ObjectsDep) -> StreamingResponse:
    """The item's cloud decimated for display by the worker (binary PLY with colours)."""
    item = _item(store, job_id, index, tenant)
    return _relay(objects, item.outputs.get("preview"), f"item {index} of job {job_id}", "item",
                  item.state.value)


@router.get("/{job_id}/items/{index}/frames/{frame}/preview.ply", response_class=StreamingResponse,
            responses=_RESPONSES)
def get_frame_preview(job_id: str, index: Index, frame: Index, tenant: TenantDep, store: StoreDep,
                      objects: ObjectsDep) -> StreamingResponse:
    """One measured frame's cloud of a video item, decimated for display (binary PLY)."""
    item = _item(store, job_id, index, tenant)
    record = next((f for f in item.frames if f.index == frame), None)
    if record is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"item {index} of job {job_id} has no frame {frame} (yet)")
    return _relay(objects, record.outputs.get("preview"), f"frame {frame} of item {index} of job {job_id}",
                  "frame", record.state.value)

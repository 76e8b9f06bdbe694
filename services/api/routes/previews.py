"""An item's (or a video frame's) display cloud and overlay picture, streamed through the API.

``GET /v1/jobs/{id}/items/{n}/preview.ply`` and ``.../items/{n}/frames/{f}/preview.ply``; the
same with ``overlay.jpg`` (the fit drawn on the photo; ``overlay.png``, the name before it was a
JPEG, still answers, with the picture as stored), and ``items/{n}/box.glb`` (the fitted box
as a textured glTF model, when the item asked for the glb format), and ``items/{n}/tracked_points.json``
(a video whose points were marked on one frame: each frame's tracked points, or why it was left
out). The web page draws the cloud with WebGL
and shows the overlay from its own origin, so these routes relay the worker's objects (`relay`).
Another tenant's job answers 404, like every job route.
"""

from __future__ import annotations

from pathlib import PurePosixPath
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, status
from fastapi.responses import StreamingResponse
from prism_common.records import FrameRecord, ItemRecord
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

from prismcore.formats import media_type

from ..deps import ObjectsDep, StoreDep, TenantDep
from ..relay import relay_object
from .jobs import own_job

__all__ = ["router"]

router = APIRouter(prefix="/jobs", tags=["jobs"])

_PLY = {"content": {"application/octet-stream": {}},
        "description": "Binary little-endian PLY: float32 x, y, z (mm) and uchar red, green, blue."}
_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: _PLY, 404: {"description": "No such job, item, frame or preview"}
}
Index = Annotated[int, Path(ge=0)]


def _item(store: JobStore, job_id: str, index: int, tenant: str) -> ItemRecord:
    job = own_job(store, job_id, tenant)
    if index >= len(job.items):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} has no item {index}")
    return job.items[index]


def _relay(objects: ObjectStore, key: str | None, what: str, noun: str, state: str,
           kind: str = "preview") -> StreamingResponse:
    if key is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"{what} has no {kind} (the {noun} is {state})")
    media = media_type(kind)  # the format table's
    if kind == "overlay":  # a JPEG (overlay.jpg), or a PNG for a job from before
        media = _OVERLAY_MEDIA.get(PurePosixPath(key).suffix, "image/jpeg")
    response = relay_object(objects, key, media, max_age_s=300)
    if response is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"the {kind} of {what} is gone")
    return response


def _frame(item: ItemRecord, job_id: str, index: int, frame: int) -> FrameRecord:
    record = next((f for f in item.frames if f.index == frame), None)
    if record is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"item {index} of job {job_id} has no frame {frame} (yet)")
    return record


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
    record = _frame(_item(store, job_id, index, tenant), job_id, index, frame)
    return _relay(objects, record.outputs.get("preview"), f"frame {frame} of item {index} of job {job_id}",
                  "frame", record.state.value)


_OVERLAY_MEDIA = {".jpg": "image/jpeg", ".png": "image/png", ".webp": "image/webp"}
_OVERLAY_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/jpeg": {}, "image/png": {}}, "description": "The fit drawn on the photo: "
          "clicks, fitted faces and corners, residuals, dimensions. A JPEG; a job from before the "
          "overlay was a JPEG has a PNG (its Content-Type says which)."},
    404: {"description": "No such job, item, frame or overlay"}}


@router.get("/{job_id}/items/{index}/overlay.jpg", response_class=StreamingResponse,
            responses=_OVERLAY_RESPONSES)
def get_overlay(job_id: str, index: Index, tenant: TenantDep, store: StoreDep,
                objects: ObjectsDep) -> StreamingResponse:
    """The item's overlay picture (JPEG): whether the fit sits on the box, at a glance."""
    item = _item(store, job_id, index, tenant)
    return _relay(objects, item.outputs.get("overlay"), f"item {index} of job {job_id}", "item",
                  item.state.value, "overlay")


@router.get("/{job_id}/items/{index}/overlay.png", response_class=StreamingResponse,
            responses=_OVERLAY_RESPONSES, deprecated=True)
def get_overlay_png(job_id: str, index: Index, tenant: TenantDep, store: StoreDep,
                    objects: ObjectsDep) -> StreamingResponse:
    """The same picture as overlay.jpg, under the name it had when it was a PNG (links made then
    keep working): the overlay as stored, with its own Content-Type."""
    return get_overlay(job_id, index, tenant, store, objects)


@router.get("/{job_id}/items/{index}/frames/{frame}/overlay.jpg", response_class=StreamingResponse,
            responses=_OVERLAY_RESPONSES)
def get_frame_overlay(job_id: str, index: Index, frame: Index, tenant: TenantDep, store: StoreDep,
                      objects: ObjectsDep) -> StreamingResponse:
    """One measured frame's overlay picture (JPEG) of a video item."""
    record = _frame(_item(store, job_id, index, tenant), job_id, index, frame)
    return _relay(objects, record.outputs.get("overlay"), f"frame {frame} of item {index} of job {job_id}",
                  "frame", record.state.value, "overlay")


@router.get("/{job_id}/items/{index}/frames/{frame}/overlay.png", response_class=StreamingResponse,
            responses=_OVERLAY_RESPONSES, deprecated=True)
def get_frame_overlay_png(job_id: str, index: Index, frame: Index, tenant: TenantDep, store: StoreDep,
                          objects: ObjectsDep) -> StreamingResponse:
    """The same picture as the frame's overlay.jpg, under its name from when it was a PNG."""
    return get_frame_overlay(job_id, index, frame, tenant, store, objects)


@router.get("/{job_id}/items/{index}/box.glb", response_class=StreamingResponse,
            responses={200: {"content": {"model/gltf-binary": {}},
                             "description": "The fitted box as binary glTF (metres, Y up), its visible "
                                            "faces textured from the photo."},
                       404: {"description": "No such job or item, or no glb (not among its formats)"}})
def get_box_model(job_id: str, index: Index, tenant: TenantDep, store: StoreDep,
                  objects: ObjectsDep) -> StreamingResponse:
    """The item's box model (box.glb), relayed so the page loads it from its own origin."""
    item = _item(store, job_id, index, tenant)
    return _relay(objects, item.outputs.get("glb"), f"item {index} of job {job_id}", "item",
                  item.state.value, "glb")


@router.get("/{job_id}/items/{index}/tracked_points.json", response_class=StreamingResponse,
            responses={200: {"content": {"application/json": {}},
                             "description": "Per frame index, its seven tracked points [[x, y] x 7] "
                                            "and their quality, or the reason the frame was left out."},
                       404: {"description": "No such job or item, or no tracking (no points_frame, "
                                            "or not tracked yet)"}})
def get_tracked_points(job_id: str, index: Index, tenant: TenantDep, store: StoreDep,
                       objects: ObjectsDep) -> StreamingResponse:
    """The points of a video marked on one frame (points_frame), tracked to each selected frame
    (tracked_points.json), relayed so the page draws the track from its own origin."""
    item = _item(store, job_id, index, tenant)
    return _relay(objects, item.outputs.get("tracked_points"), f"item {index} of job {job_id}", "item",
                  item.state.value, "tracked_points")

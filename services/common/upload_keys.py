"""Object keys of an upload and of what the worker derives from a video upload.

``uploads/{tenant hash}/{id}`` is the uploaded file; beside it ``{id}.video.json`` (the video's
probe, or the error that stopped it) and under ``{id}.frames/`` each decoded frame as
``frame_000123.png`` (lossless), or ``frame_000123.error.json`` when it could not be decoded;
under ``{id}.points/`` what the point search found (`points_key`).
Built from checked segments only (`object_key`): the API and the worker agree on them, and no
request can name another object.
"""

from __future__ import annotations

import hashlib

from prismcore.spec import frame_folder

from .storage import object_key

__all__ = ["frame_error_key", "frame_png_key", "points_key", "points_prefix", "tenant_hash", "upload_key",
           "video_info_key"]


def tenant_hash(tenant: str) -> str:
    # Tenant names are free text; a hash is always a safe key segment and does not expose them.
    return hashlib.sha256(tenant.encode()).hexdigest()[:32]


def upload_key(tenant: str, upload_id: str) -> str:
    return object_key("uploads", tenant_hash(tenant), upload_id)


def video_info_key(tenant: str, upload_id: str) -> str:
    return object_key("uploads", tenant_hash(tenant), f"{upload_id}.video.json")


def frame_png_key(tenant: str, upload_id: str, frame: int) -> str:
    return object_key("uploads", tenant_hash(tenant), f"{upload_id}.frames", f"{frame_folder(frame)}.png")


def frame_error_key(tenant: str, upload_id: str, frame: int) -> str:
    return object_key("uploads", tenant_hash(tenant), f"{upload_id}.frames",
                      f"{frame_folder(frame)}.error.json")


def points_prefix(tenant: str, upload_id: str) -> str:
    """The folder of every point search on the upload (deleted with it)."""
    return object_key("uploads", tenant_hash(tenant), f"{upload_id}.points") + "/"


def points_key(tenant: str, upload_id: str, frame: int | None, hint: tuple[int, int] | None) -> str:
    """What the point search found in the photo (or a video's frame `frame`) around `hint`
    (whole px: one search per pixel, however the hint was written)."""
    name = "photo" if frame is None else frame_folder(frame)
    if hint is not None:
        name += f"_hint_{hint[0]}_{hint[1]}"
    return points_prefix(tenant, upload_id) + object_key(f"{name}.json")

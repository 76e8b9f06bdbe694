"""Object keys of an upload and of what the worker derives from a video upload.

``uploads/{tenant hash}/{id}`` is the uploaded file; beside it ``{id}.video.json`` (the video's
probe, or the error that stopped it) and under ``{id}.frames/`` each decoded frame as
``frame_000123.png`` (lossless), or ``frame_000123.error.json`` when it could not be decoded.
Built from checked segments only (`object_key`): the API and the worker agree on them, and no
request can name another object.
"""

from __future__ import annotations

import hashlib

from prismcore.spec import frame_folder

from .storage import object_key

__all__ = ["frame_error_key", "frame_png_key", "tenant_hash", "upload_key", "video_info_key"]


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

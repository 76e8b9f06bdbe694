"""Frames of an uploaded video, for a person to mark: the video's probe and one frame as a PNG.

The web page shows the frame exactly as the worker will measure it: decoded by the same code
(`prismcore.video`) from the same bytes, whatever the codec (browsers cannot play MJPEG AVI,
for one). What is written (keys in `prism_common.upload_keys`): ``{id}.video.json``, the probe
(frame count, fps, size, codec, duration) or ``{"error": ...}`` when the upload is not a video
that decodes; the frame's PNG, or its ``.error.json`` when that frame does not decode.

Idempotent: an error or a frame already written is not redone; decoding is deterministic, so a
repeat writes the same objects. The last video read stays on local disk (one per process), so
a person stepping through frames does not download it again for each one.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path

from botocore.exceptions import ClientError
from prism_common.storage import is_missing
from prism_common.upload_keys import frame_error_key, frame_png_key, video_info_key

from prismcore import InputError
from prismcore.containers import HEAD_BYTES, video_container
from prismcore.video import iter_frames, probe_video

from . import context
from .video_item import client_message, png_bytes

__all__ = ["extract_frame"]

log = logging.getLogger(__name__)
_CHUNK = 1 << 20
_local: dict[str, Path] = {}  # upload id -> its file, at most one entry
_folder: tempfile.TemporaryDirectory | None = None  # removed when the process exits


def extract_frame(upload_id: str, frame: int) -> None:
    """Probe the upload (unless done) and store frame `frame` as a PNG (unless done or out of
    range). A file that is not a decodable video gets its error recorded, never raised."""
    written = _extract(upload_id, frame)
    if written and context.store().get_upload(upload_id) is None:
        # The upload expired while this ran: its sweep has gone by, so leave nothing behind.
        context.objects().delete_keys(written)


def _extract(upload_id: str, frame: int) -> list[str]:
    """What `extract_frame` does; returns the keys it wrote."""
    written: list[str] = []
    upload = context.store().get_upload(upload_id)
    if upload is None or frame < 0:
        log.warning("no frame %s of upload %s to extract", frame, upload_id)
        return written
    tenant, name = upload["tenant"], upload.get("name") or upload_id
    objects = context.objects()
    info_key = video_info_key(tenant, upload_id)
    png_key, error_key = frame_png_key(tenant, upload_id, frame), frame_error_key(tenant, upload_id, frame)
    info = objects.get_json(info_key)
    if info is not None and ("error" in info or frame >= info["frame_count"]
                             or objects.exists(png_key) or objects.exists(error_key)):
        return written
    try:
        if info is None:
            head = objects.client.get_object(Bucket=objects.bucket, Key=upload["key"],
                                             Range=f"bytes=0-{HEAD_BYTES - 1}")["Body"].read()
            if video_container(head) is None:  # a photo: no need to fetch the whole file
                objects.put_json(info_key, {"error": f"{name!r} is not a video (AVI, MP4, MOV or "
                                              f"MKV): it starts with {head[:8]!r}"})
                return [info_key]
        path = _local_copy(upload_id, upload["key"])
    except ClientError as exc:
        if not is_missing(exc):
            raise  # the store's trouble: retried
        # The record outlived the file (deleted by hand, or expiring): say so, once, for good.
        objects.put_json(info_key, {"error": f"{name!r} is no longer stored: upload it again"})
        return [info_key]
    if info is None:
        try:
            info = asdict(probe_video(path, max_pixels=context.settings().max_pixels))
        except InputError as exc:
            objects.put_json(info_key, {"error": client_message(exc, path, name)})
            return [info_key]
        objects.put_json(info_key, info)
        written.append(info_key)
    if frame >= info["frame_count"]:
        return written
    try:
        for _, rgb in iter_frames(path, [frame]):
            objects.put_bytes(png_key, png_bytes(rgb), "image/png")
            written.append(png_key)
    except InputError as exc:
        objects.put_json(error_key, {"error": client_message(exc, path, name)})
        written.append(error_key)
    return written


def _local_copy(upload_id: str, key: str) -> Path:
    """The upload on local disk: the one kept from the last call, or fetched in its place."""
    global _folder
    if upload_id in _local and _local[upload_id].exists():
        return _local[upload_id]
    if _folder is None:
        _folder = tempfile.TemporaryDirectory(prefix="prism-upload-frames-")
    for old in _local.values():
        old.unlink(missing_ok=True)
    _local.clear()
    path = Path(_folder.name) / "video"
    partial = path.with_suffix(".part")
    objects = context.objects()
    with objects.client.get_object(Bucket=objects.bucket, Key=key)["Body"] as body, partial.open("wb") as f:
        shutil.copyfileobj(body, f, _CHUNK)
    partial.replace(path)  # a fetch cut short never passes for the whole file
    _local[upload_id] = path
    return path

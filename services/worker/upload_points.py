"""The box and its reference points found in an upload, for the web page's "Find points".

`find_upload_points` decodes the upload as a job would (`prismcore.io.images.load_image`; a
video's frame through `video.extract_frame`, the very PNG the page shows) and runs the
zero-click search (`prismcore.locate.search.find_points`). It writes one JSON document beside the
upload (`prism_common.upload_keys.points_key`), which the API serves:

* found: ``points`` (p1..p7, image (x, y) px), ``side_face``, ``confidence``, ``faces`` (the
  found faces' quads), ``warnings``; ``reason`` null;
* refused: ``reason`` (no box, two candidates, one face, uncertain: words a person can act
  on), ``points`` null;
* ``{"error": ...}`` when the file (or frame) does not decode or is gone;
* ``{"error": ..., "retry": true}`` when the search's task gave up (the store down through its
  retries, a time limit): the API says so once and then forgets it, so asking again searches
  again instead of meeting the same passing trouble until the upload expires.

Idempotent: the search is deterministic, so a document already written is not redone.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from botocore.exceptions import ClientError
from prism_common.storage import is_missing
from prism_common.upload_keys import frame_error_key, frame_png_key, points_key, video_info_key

from prismcore import InputError
from prismcore.io import load_image
from prismcore.locate import Found, find_points

from . import video
from .context import WorkerContext

__all__ = ["find_upload_points", "found_document", "search_failed"]

log = logging.getLogger(__name__)

Hint = tuple[int, int]


def find_upload_points(ctx: WorkerContext, upload_id: str, frame: int | None, hint: Hint | None) -> None:
    """Search the photo (or frame `frame` of a video) around `hint` and store what was found."""
    upload = ctx.store.get_upload(upload_id)
    if upload is None:
        log.warning("no upload %s to find points in", upload_id)
        return
    key = points_key(upload["tenant"], upload_id, frame, hint)
    objects = ctx.objects
    if objects.exists(key):
        return
    try:
        image = _image(ctx, upload_id, upload, frame)
        doc = found_document(find_points(image, hint=hint), image.shape[1], image.shape[0])
    except InputError as exc:
        doc = {"error": str(exc)}
    objects.put_json(key, doc)
    if ctx.store.get_upload(upload_id) is None:
        objects.delete_keys([key])  # expired meanwhile: its sweep has gone by


def search_failed(ctx: WorkerContext, upload_id: str, frame: int | None, hint: Hint | None,
                  reason: str) -> None:
    """Record a search whose task gave up (a time limit, a store down), so the page that waits
    on it hears why instead of asking again and again; marked ``retry``: the cause may pass."""
    upload = ctx.store.get_upload(upload_id)
    if upload is not None:
        ctx.objects.put_json(points_key(upload["tenant"], upload_id, frame, hint),
                             {"error": f"the point search {reason}" if reason.startswith("took")
                              else f"the point search failed: {reason}", "retry": True})


def found_document(found: Found, width: int, height: int) -> dict[str, Any]:
    """What the API answers (`prism_api.schemas.FoundPointsPublic`): the points only when they
    may be used."""
    accepted = found.ok and found.points is not None
    points = found.points.as_dict() if accepted and found.points is not None else None
    return {
        "width": width, "height": height,
        "points": None if points is None else
        {k: [round(v[0], 2), round(v[1], 2)] for k, v in points.items() if v is not None},
        "side_face": found.side_face if accepted else None,
        "confidence": round(found.confidence, 3),
        "reason": found.reason,
        "warnings": list(found.warnings),
        "faces": [[[round(float(x), 1), round(float(y), 1)] for x, y in quad] for quad in found.faces]
        if accepted else [],
    }


def _image(ctx: WorkerContext, upload_id: str, upload: dict[str, str], frame: int | None) -> np.ndarray:
    """The photo, or the video's frame, RGB (H, W, 3), as a job decodes it.

    Raises
    ------
    InputError
        Not a photo the engine reads (or not a video, a frame past the end, one that does not
        decode), too many pixels, or the file is gone.
    """
    name, tenant, objects = upload.get("name") or upload_id, upload["tenant"], ctx.objects
    if frame is None:
        try:
            data = objects.get_bytes(upload["key"])
        except ClientError as exc:
            if not is_missing(exc):
                raise  # the store's trouble: retried
            raise InputError(f"{name!r} is no longer stored: upload it again") from None
        return load_image(data, max_pixels=ctx.settings.max_pixels, name=name)
    video.extract_frame(ctx, upload_id, frame)
    info = objects.get_json(video_info_key(tenant, upload_id))
    if info is not None and "error" in info:
        raise InputError(info["error"])
    if info is not None and frame >= info["frame_count"]:
        raise InputError(f"no frame {frame}: {name!r} has {info['frame_count']} frames "
                         f"(0-{info['frame_count'] - 1})")
    if (failed := objects.get_json(frame_error_key(tenant, upload_id, frame))) is not None:
        raise InputError(failed["error"])
    png = objects.get_bytes(frame_png_key(tenant, upload_id, frame))
    return load_image(png, max_pixels=ctx.settings.max_pixels, name=f"frame {frame} of {name!r}")

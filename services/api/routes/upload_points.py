"""The box and its reference points found in an upload: the web page's "Find points".

``GET /v1/uploads/{id}/points?hint=x,y`` (``&frame=n`` for a video). The API decodes nothing
(no numpy or OpenCV here): like a video's frames (`upload_video`), it sends `prism.find_points`
to a worker, once however often the page polls (an expiring claim), and answers 202 with
Retry-After until the worker has stored what it found beside the upload; then 200 with the
points, or with the reason the search refused; 503 once when the search's task gave up on a
cause that may pass (asking again searches again). Another tenant's upload answers 404.
"""

from __future__ import annotations

import math
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, status
from fastapi.responses import JSONResponse
from prism_common.queue import TASK_FIND_POINTS
from prism_common.upload_keys import points_key
from prism_common.upload_records import upload_probe

from ..deps import CeleryDep, ObjectsDep, StoreDep, TenantDep
from ..problems import Problem
from ..schemas import FoundPointsPublic
from .upload_video import _PENDING, CLAIM_TTL_S, RETRY_AFTER_S, _own_upload, _refused, ask_worker

router = APIRouter(prefix="/uploads", tags=["uploads"])

_HINT_PATTERN = r"^\s*[-+0-9.eE]+\s*,\s*[-+0-9.eE]+\s*$"
_MAX_SIDE = 2**31 - 1


def _invalid(parameter: str, detail: str) -> Problem:
    return Problem("validation", detail, errors=[{"parameter": parameter, "detail": detail}])


def _hint(text: str | None, size: tuple[int, int] | None) -> tuple[int, int] | None:
    """The hint "x,y" as whole px (a hint is a point on the box: a pixel is plenty, and one
    search per pixel is kept); inside the `size` (w, h) image when known."""
    if text is None:
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise _invalid("hint", f"hint {text!r} is not x,y (pixels, e.g. 320,240)") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise _invalid("hint", f"hint {text!r} is not x,y (pixels, e.g. 320,240)")
    hint = (round(x), round(y))
    # Without a size (a probe that could not read it) the hint is still bounded: it names the
    # stored answer, whose key has room for sides up to OpenCV's (int) image size.
    w, h = size or (_MAX_SIDE, _MAX_SIDE)
    if not (0 <= hint[0] < w and 0 <= hint[1] < h):
        where = f"the {w}x{h} image" if size else "any image"
        raise _invalid("hint", f"hint {text!r} is outside {where}")
    return hint


@router.get("/{upload_id}/points", response_model=FoundPointsPublic,
            responses={**_PENDING, 404: {"description": "No such upload"},
                       422: {"description": "A bad hint or frame, or a file (frame) that does not decode"},
                       503: {"description": "The search gave up (the store down, a time limit): "
                                            "ask again to search again"}})
def get_points(upload_id: str, tenant: TenantDep, store: StoreDep, objects: ObjectsDep, celery: CeleryDep,
               hint: Annotated[str | None, Query(
                   pattern=_HINT_PATTERN, max_length=64,
                   description="x,y (px): a point on the box wanted; without it, the most box-like "
                               "object near the centre. Rounded to whole px.")] = None,
               frame: Annotated[int | None, Query(
                   ge=0, le=10_000_000, description="A video's frame to search (required for a "
                                                    "video; not for a photo).")] = None,
               ) -> FoundPointsPublic | JSONResponse:
    """The box and its reference points P1..P7 found in an uploaded photo (or a video's frame),
    for a person to check; or why none were (the first call starts the search)."""
    upload = _own_upload(store, upload_id, tenant)
    probe = upload_probe(upload) or {}
    if probe.get("kind") == "video" and frame is None:
        raise _invalid("frame", f"upload {upload_id} is a video: say which frame to search (frame=N)")
    if probe.get("kind") == "image" and frame is not None:
        raise _invalid("frame", f"upload {upload_id} is a photo: it has no frame {frame}")
    count = probe.get("frame_count")
    if frame is not None and isinstance(count, int) and count > 0 and frame >= count:
        raise _invalid("frame", f"upload {upload_id} has {count} frames (0-{count - 1}): no frame {frame}")
    size = (probe["width"], probe["height"]) if isinstance(probe.get("width"), int) and \
        isinstance(probe.get("height"), int) else None
    found_hint = _hint(hint, size)
    key = points_key(upload["tenant"], upload_id, frame, found_hint)
    doc = objects.get_json(key)
    if doc is None:
        return ask_worker(store.claim_points(upload_id, key.rsplit("/", 1)[-1], CLAIM_TTL_S), celery,
                          TASK_FIND_POINTS, [upload_id, frame, found_hint and list(found_hint)],
                          f"searching upload {upload_id} for the box")
    if doc.get("retry"):
        # The search's task gave up on a cause that may pass (the store down, a time limit
        # under load): said once, then forgotten, so the next ask searches again.
        objects.delete_keys([key])
        store.release_points(upload_id, key.rsplit("/", 1)[-1])
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, f"{doc['error']}; ask again to search "
                            "again", headers={"Retry-After": str(RETRY_AFTER_S)})
    if "error" in doc:
        raise _refused(doc)
    return FoundPointsPublic(id=upload_id, frame=frame, hint=found_hint, **doc)

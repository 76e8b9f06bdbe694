"""Checks of a submitted job that need the settings or the store, beyond its schema.

Failures are reported like schema errors (422, one entry per problem with its location), so a
client handles both the same way. Reference points are checked against the photos' pixel sizes
recorded when they were uploaded (`prism_api.probe`), by the engine's own checks
(`prismcore.faces`), so a job the engine would refuse for its points is refused here instead.
"""

from __future__ import annotations

import json
import re
from typing import Any

from fastapi.exceptions import RequestValidationError
from prism_common.outbound import check_webhook_url
from prism_common.references import ReferenceError, check_reference, parse_reference
from prism_common.settings import Settings
from prism_common.store import JobStore
from prism_common.upload_records import upload_probe

from prismcore.spec import ReferencePoints, ScanSpec, search_area_problem

from .schemas import JobCreate

__all__ = ["check_job", "point_problem"]

_POINT = re.compile(r"\bpoint (p[1-7])\b")

_MAX_REPORTED = 50  # a 5000-item batch with one bad upload gets a readable answer, not 5000 lines


def point_problem(spec: ScanSpec, points: ReferencePoints, front: tuple[int, int],
                  side: tuple[int, int]) -> tuple[str | None, str] | None:
    """Why the engine would refuse `points` on photos of `front` and `side` size (height, width
    px, as the engine sees them), and the point at fault (None: the points as a whole); or None.

    The checks `prismcore.pipeline.plan_scan` makes before it looks at a pixel: every point in
    its photo, each face's corners in order, convex and apart.
    """
    # The engine (numpy) is imported on the first job whose photos have known sizes.
    from prismcore.errors import InputError
    from prismcore.faces import (
        clicked_quads,
        paper_rectangles,
        quad_labels,
        resolve_side_face,
        validate_points,
        validate_quad,
    )
    from prismcore.pipeline import _side_height_guess

    try:
        validate_points(points, front, side)
        camera = spec.camera
        if camera is not None and camera.has_distortion:
            return None  # the engine checks the quads on undistorted points, after decoding
        face = resolve_side_face(points, spec.side_face, two_photo=spec.two_photo)
        labels: tuple[tuple[str | None, ...] | None, tuple[str | None, ...] | None]  # None: unnamed corners
        if spec.method == "paper":
            quads, labels = paper_rectangles(points, two_photo=spec.two_photo, side_face=face), (None, None)
        else:
            this = spec.model_copy(update={"points": points})
            quads = clicked_quads(points, two_photo=spec.two_photo, side_height_px=_side_height_guess(this),
                                  side_face=face)
            labels = quad_labels(quads)
        validate_quad(quads.front, "front face", front, labels=labels[0])
        validate_quad(quads.side, "side face", side, labels=labels[1])
    except InputError as exc:
        named = _POINT.search(str(exc))
        return (named.group(1) if named else None), str(exc)
    return None


def _size(probe: dict[str, Any] | None) -> tuple[int, int] | None:
    if probe and isinstance(probe.get("width"), int) and isinstance(probe.get("height"), int):
        return probe["height"], probe["width"]
    return None


def _kind_problem(item: ScanSpec, field: str, probe: dict[str, Any] | None) -> tuple[tuple, str] | None:
    """Where and why the upload named by `field` is the wrong kind for the item: a video as a
    photo, a photo as a video, frame indices past the video's end; None when it fits (or its
    probe is unknown)."""
    kind = (probe or {}).get("kind")
    if kind == "video" and (field == "side_image" or not item.is_video):
        return (field,), (f"{field}: the upload is a video: measure it with `frames` (e.g. {{}} for "
                          "every frame, or {\"every\": 10}) in single-photo mode")
    if kind == "image" and field == "image" and item.is_video:
        return ("frames",), "frames: the image is a photo, not a video: drop frames (and frame_points)"
    count = (probe or {}).get("frame_count")
    indices = item.frames.indices if item.frames is not None else None
    if kind == "video" and isinstance(count, int) and indices:
        past = sorted(n for n in indices if n >= count)
        if past:
            where = ("frame_points", str(past[0])) if item.frame_points else ("frames", "indices")
            return where, (f"frames: indices {past} are past the video's end: it has {count} "
                           f"frames (0-{count - 1})")
    return None


def check_job(job: JobCreate, settings: Settings, store: JobStore, tenant: str,
              raw: bytes | None = None) -> set[str]:
    """Raise RequestValidationError naming every item (and field) the service will not run;
    else return the ids of the uploads the job reads. `raw` is the body as sent, for pointers
    that name its own keys or indices."""
    errors: list[dict[str, Any]] = []

    def fail(loc: tuple, msg: str) -> None:
        errors.append({"type": "value_error", "loc": ("body", *loc), "msg": msg})

    if len(job.items) > settings.max_items_per_job:
        fail(("items",), f"at most {settings.max_items_per_job} items per job, got {len(job.items)}")
    if job.webhook_url is not None:
        try:  # the worker checks again before each delivery, resolving the host then
            check_webhook_url(job.webhook_url, settings, resolve=False)
        except ReferenceError as exc:
            fail(("webhook_url",), f"webhook_url: {exc}")
    # Explicit frame indices are known now; other selections are counted when the video is read.
    named = sum(len(item.frames.indices) for item in job.items if item.frames and item.frames.indices)
    if named > settings.max_frames_per_job:
        fail(("items",), f"the job's videos name {named} frames, over the cap of "
                         f"{settings.max_frames_per_job} frames per job")
    owners: dict[str, str | None] = {}  # a batch often reuses one upload: look it up once
    sizes: dict[str, tuple[int, int] | None] = {}
    probes: dict[str, dict[str, Any] | None] = {}
    for i, item in enumerate(job.items):
        if len(errors) >= _MAX_REPORTED:
            break
        shapes: dict[str, tuple[int, int] | None] = {}
        for field in ("image", "side_image"):
            text = getattr(item, field)
            if text is None:
                continue
            try:
                ref = parse_reference(text)
                if ref.kind == "upload" and ref.upload_id not in owners:
                    upload = store.get_upload(ref.upload_id)
                    owners[ref.upload_id] = upload["tenant"] if upload else None
                    probes[ref.upload_id] = upload_probe(upload)
                    sizes[ref.upload_id] = _size(probes[ref.upload_id])
                check_reference(ref, settings, tenant=tenant, upload_owner=owners.get(ref.upload_id))
                shapes[field] = sizes.get(ref.upload_id) if ref.kind == "upload" else None
                if ref.kind == "upload" and (problem := _kind_problem(item, field, probes[ref.upload_id])):
                    fail(("items", i, *problem[0]), f"item {i} {problem[1]}")
                    shapes[field] = None
            except ReferenceError as exc:
                fail(("items", i, field), f"item {i} {field}: {exc}")
                shapes[field] = None
        front = shapes.get("image")
        side = shapes.get("side_image") if item.two_photo else front
        if front is None or side is None:
            continue  # a URL, or an upload whose size is not known: the worker checks
        marks = [(("points",), item.points)] if item.points is not None else \
            [(("frame_points", str(n)), p) for n, p in (item.frame_points or {}).items()]
        for where, points in marks:
            if (found := point_problem(item, points, front, side)) is not None:
                name, message = found
                fail(("items", i, *where, *([name] if name else [])), f"item {i}: {message}")
                break
        auto = item.auto_points
        if auto is not None and (found := search_area_problem(auto.hint, auto.roi, front[1], front[0])):
            fail(("items", i, "auto_points", found[0]), f"item {i}: auto_points.{found[1]}")
    if errors:
        body: Any = None
        if raw is not None:
            try:
                body = json.loads(raw)
            except ValueError:
                body = None
        raise RequestValidationError(errors[:_MAX_REPORTED], body=body)
    return set(owners)

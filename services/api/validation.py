"""Checks of a submitted job that need the settings or the store, beyond its schema.

Failures are reported like schema errors (422, one entry per problem with its location), so a
client handles both the same way. Reference points are checked against the photos' pixel sizes
recorded when they were uploaded (`prism_api.probe`), by the engine's own checks
(`prismcore.geometry.faces`), so a job the engine would refuse for its points is refused here instead.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any, NamedTuple

from fastapi.exceptions import RequestValidationError
from prism_common.outbound import check_webhook_url
from prism_common.references import ReferenceError, check_reference, parse_reference
from prism_common.settings import Settings
from prism_common.stations import StationPublic
from prism_common.store import JobStore
from prism_common.upload_records import upload_probe

from prismcore.errors import InputError
from prismcore.spec import (
    JOINT_MAX_PIXELS,
    FrameSelection,
    ItemKind,
    ReferencePoints,
    ScanSpec,
    search_area_problem,
    view_spec,
)
from prismcore.video import points_frame_problem, span_problem

from .schemas import JobCreate

__all__ = ["KINDS", "check_job", "point_problem"]

_POINT = re.compile(r"\bpoint (p[1-7])\b")

_MAX_REPORTED = 50  # a 5000-item batch with one bad upload gets a readable answer, not 5000 lines


def point_problem(spec: ScanSpec, points: ReferencePoints, front: tuple[int, int],
                  side: tuple[int, int]) -> tuple[str | None, str] | None:
    """Why the engine would refuse `points` on photos of `front` and `side` size (height, width
    px, as the engine sees them), and the point at fault (None: the points as a whole); or None.

    The checks `prismcore.scan.plan_scan` makes before it looks at a pixel (`prismcore.scan.marked_quads`
    builds and checks the faces for both): every point in its photo, each face's corners in order,
    convex and apart.
    """
    # The engine (numpy) is imported on the first job whose photos have known sizes.
    from prismcore.errors import InputError
    from prismcore.geometry import resolve_side_face, validate_points
    from prismcore.scan import marked_quads

    try:
        validate_points(points, front, side)
        camera = spec.camera
        if camera is not None and camera.has_distortion:
            return None  # the engine checks the faces on undistorted points, after decoding
        # The second face read first, as this check always did: a front in a line is said as
        # points that "do not span a face" (the engine's plan_scan checks the front alone first)
        face = resolve_side_face(points, spec.side_face, two_photo=spec.two_photo)
        marked_quads(spec.model_copy(update={"points": points}), face, front, side)
    except InputError as exc:
        named = _POINT.search(str(exc))
        return (named.group(1) if named else None), str(exc)
    return None


def _size(probe: dict[str, Any] | None) -> tuple[int, int] | None:
    if probe and isinstance(probe.get("width"), int) and isinstance(probe.get("height"), int):
        return probe["height"], probe["width"]
    return None


def _kind_problem(item: ScanSpec, field: str, probe: dict[str, Any] | None,
                  max_span: int) -> tuple[tuple, str] | None:
    """Where and why the upload named by `field` is the wrong kind for the item: a video as a
    photo, a photo as a video, frame indices (or the marked frame, points_frame) past the video's
    end, a tracking from points_frame that would read over `max_span` frames; None when it fits
    (or its probe is unknown). `field` "view": a photo of an item's views."""
    kind = (probe or {}).get("kind")
    if field == "view":
        return ((), "the upload is a video: a view is a photo (a video's frames are measured as one "
                    "box with frame_points and fit \"joint\")") if kind == "video" else None
    if kind == "video" and (field == "side_image" or not item.is_video):
        return (field,), (f"{field}: the upload is a video: measure it with `frames` (e.g. {{}} for "
                          "every frame, or {\"every\": 10}) in single-photo mode")
    if kind == "image" and field == "image" and item.is_video:
        return ("frames",), "frames: the image is a photo, not a video: drop frames (and frame_points)"
    count = (probe or {}).get("frame_count")
    marked = item.points_frame
    if kind == "video" and isinstance(count, int) and (problem := points_frame_problem(marked, count)):
        return ("points_frame",), problem
    indices = item.frames.indices if item.frames is not None else None
    if kind == "video" and isinstance(count, int) and indices:
        past = sorted(n for n in indices if n >= count)
        if past:
            where = ("frame_points", str(past[0])) if item.frame_points else ("frames", "indices")
            return where, (f"frames: indices {past} are past the video's end: it has {count} "
                           f"frames (0-{count - 1})")
    if kind == "video" and isinstance(count, int) and marked is not None and item.frames is not None:
        frames = _selected(item.frames, probe or {})
        if frames is not None and (problem := span_problem(frames, marked, max_span)):
            return ("points_frame",), problem
    return None


def _selected(selection: FrameSelection, probe: dict[str, Any]) -> list[int] | None:
    """The frames `selection` picks of the probed video, when that is known before it is decoded
    (not for `sharpest`, nor a selection the worker will refuse)."""
    if selection.sharpest is not None:
        return None
    # Only for an item marked on one frame: the API loads no engine otherwise.
    from prismcore.io import VideoInfo
    from prismcore.video import select_frames

    fps = probe.get("fps")
    rate = float(fps) if isinstance(fps, int | float) else 0.0
    info = VideoInfo(frame_count=probe["frame_count"], fps=rate,
                     width=int(probe.get("width") or 0), height=int(probe.get("height") or 0),
                     codec=str(probe.get("codec") or ""), duration_s=0.0)
    try:  # no decoding without `sharpest`: the path only names the video in messages
        return select_frames("upload", selection, info, max_frames=max(1, probe["frame_count"]))
    except InputError:
        return None


def _check_views(item: ScanSpec, i: int, shapes: dict[str, tuple[int, int] | None],
                 fail: Callable[[tuple, str], None]) -> None:
    """The views of a joint item whose photos' sizes are known: one image size for all (one
    camera), and each view's points as the engine checks them on its photo."""
    assert item.views is not None
    first: tuple[int, tuple[int, int]] | None = None
    known = [size for k in range(len(item.views)) if (size := shapes.get(f"views/{k}/image")) is not None]
    if (total := sum(h * w for h, w in known)) > JOINT_MAX_PIXELS:
        fail(("items", i, "views"), f"item {i} views: the photos hold {total / 1e6:.0f} megapixels "
             f"together, over a joint fit's {JOINT_MAX_PIXELS / 1e6:.0f}: give fewer or smaller photos")
    for k in range(len(item.views)):
        size = shapes.get(f"views/{k}/image")
        if size is None:
            continue  # a URL, or an upload whose size is not known: the worker checks
        if first is None:
            first = (k, size)
        elif size != first[1]:
            (h0, w0), (h, w) = first[1], size
            fail(("items", i, "views", k, "image"),
                 f"item {i} views.{k}.image: the photo is {w}x{h} px, view {first[0]}'s {w0}x{h0} px: the "
                 "views of a joint fit must come from one camera at one image size")
            continue
        photo = view_spec(item, k)
        assert photo.points is not None
        if (found := point_problem(photo, photo.points, size, size)) is not None:
            name, message = found
            fail(("items", i, "views", k, "points", *([name] if name else [])),
                 f"item {i} views.{k}: {message}")


def _check_station(station_id: str, station: StationPublic | None, i: int, size: tuple[int, int] | None,
                   fail: Callable[[tuple, str], None]) -> None:
    """A station item: the tenant's station, and a photo of its camera's size when known."""
    if station is None:
        fail(("items", i, "station"), f"item {i} station: no station {station_id!r} (POST /v1/stations "
             "stores one; GET /v1/stations lists yours)")
        return
    if size is not None and size != (station.image_height, station.image_width):
        (h, w), (sh, sw) = size, (station.image_height, station.image_width)
        fail(("items", i, "image"), f"item {i} image: the photo is {w}x{h} px, station {station_id}'s "
             f"camera {sw}x{sh} px: a station measures photos of its own camera at its image size")


Fail = Callable[[tuple, str], None]
Shapes = dict[str, tuple[int, int] | None]


def _check_points(item: ScanSpec, i: int, shapes: Shapes, fail: Fail,
                  station_of: Callable[[str], StationPublic | None]) -> None:
    """An item with points (clicked, per frame, or "auto") whose photo's size is known: the
    points as the engine checks them, and the search area of "auto" inside the photo."""
    front = shapes.get("image")
    side = shapes.get("side_image") if item.two_photo else front
    if front is None or side is None:
        return  # a URL, or an upload whose size is not known: the worker checks
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


def _check_station_item(item: ScanSpec, i: int, shapes: Shapes, fail: Fail,
                        station_of: Callable[[str], StationPublic | None]) -> None:
    assert item.station is not None
    _check_station(item.station, station_of(item.station), i, shapes.get("image"), fail)


def _check_views_item(item: ScanSpec, i: int, shapes: Shapes, fail: Fail,
                      station_of: Callable[[str], StationPublic | None]) -> None:
    _check_views(item, i, shapes, fail)


class Kind(NamedTuple):
    """What the API does with an item of one kind."""

    check: Callable[[ScanSpec, int, Shapes, Fail, Callable[[str], StationPublic | None]], None]
    """Its checks beyond the schema, once its inputs' sizes are known."""
    own_formats: bool
    """Whether it keeps the spec's formats whatever the operator's defaults: a joint fit writes
    no cloud, and its spec allows no other."""


_POINTS, _JOINT = Kind(_check_points, own_formats=False), Kind(_check_points, own_formats=True)

KINDS: dict[ItemKind, Kind] = {
    "photo": _POINTS, "found": _POINTS, "video": _POINTS, "tracked": _POINTS,
    "tracked_joint": _JOINT, "frames_joint": _JOINT,
    "views": Kind(_check_views_item, own_formats=True),
    "station": Kind(_check_station_item, own_formats=False),
}
"""The API's table of item kinds: the one place it tells them apart."""


def check_job(job: JobCreate, settings: Settings, store: JobStore, tenant: str,
              raw: bytes | None = None,
              stations: Callable[[str], StationPublic | None] | None = None) -> dict[str, str | None]:
    """Raise RequestValidationError naming every item (and field) the service will not run;
    else return the uploads the job reads, each id with the file name it was sent under. `raw` is
    the body as sent, for pointers that name its own keys or indices. `stations` looks up the
    tenant's station of an id."""
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
    names: dict[str, str | None] = {}
    sizes: dict[str, tuple[int, int] | None] = {}
    probes: dict[str, dict[str, Any] | None] = {}
    known_stations: dict[str, StationPublic | None] = {}  # a batch names one station: read it once

    def station_of(station_id: str) -> StationPublic | None:
        if station_id not in known_stations:
            known_stations[station_id] = stations(station_id) if stations else None
        return known_stations[station_id]

    for i, item in enumerate(job.items):
        if len(errors) >= _MAX_REPORTED:
            break
        shapes: dict[str, tuple[int, int] | None] = {}
        # Each input as (its place in the item, the field its kind is judged as, its reference).
        inputs: list[tuple[tuple[str | int, ...], str, str | None]] = (
            [(("views", k, "image"), "view", v.image) for k, v in enumerate(item.views)]
            if item.views is not None else [((f,), f, getattr(item, f)) for f in ("image", "side_image")])
        for where, field, text in inputs:
            if text is None:
                continue
            key = "/".join(map(str, where))
            try:
                ref = parse_reference(text)
                if ref.kind == "upload" and ref.upload_id not in owners:
                    upload = store.get_upload(ref.upload_id)
                    owners[ref.upload_id] = upload["tenant"] if upload else None
                    names[ref.upload_id] = upload.get("name") if upload else None
                    probes[ref.upload_id] = upload_probe(upload)
                    sizes[ref.upload_id] = _size(probes[ref.upload_id])
                check_reference(ref, settings, tenant=tenant, upload_owner=owners.get(ref.upload_id))
                shapes[key] = sizes.get(ref.upload_id) if ref.kind == "upload" else None
                if ref.kind == "upload" and (problem := _kind_problem(item, field, probes[ref.upload_id],
                                                                       settings.tracked_max_span)):
                    if field == "view":
                        fail(("items", i, *where), f"item {i} {'.'.join(map(str, where))}: {problem[1]}")
                    else:
                        fail(("items", i, *problem[0]), f"item {i} {problem[1]}")
                    shapes[key] = None
            except ReferenceError as exc:
                fail(("items", i, *where), f"item {i} {'.'.join(map(str, where))}: {exc}")
                shapes[key] = None
        KINDS[item.kind].check(item, i, shapes, fail, station_of)
    if errors:
        body: Any = None
        if raw is not None:
            try:
                body = json.loads(raw)
            except ValueError:
                body = None
        raise RequestValidationError(errors[:_MAX_REPORTED], body=body)
    return names

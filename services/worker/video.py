"""Video: a job's video item split into frames and each frame measured; and the frames of an
uploaded video shown to a person to mark.

Split (`split_video`): read the video, select the frames, store each one as a lossless PNG and
send its scan task as soon as it is stored, so frames are measured while the split goes on; a
split works for `video_split_part_s` at a time, each part handing the rest to the next task.
One decoded frame is in memory at a time. Without a focal length, every frame's own fit is
pooled into one (one camera) before any frame is measured. With points "auto" the split also
finds each frame's points, in frame order (`prismcore.video.point_search.FrameSearch`: each search
starts at the box the frame before showed), and stores them beside the frame (``points.json``:
the points, or the search's reason, which fails that frame).

Points marked on one frame (``points_frame``): the split's first part tracks them to the
selected frames (`prismcore.video.tracked`, as `prism scan VIDEO --points-frame N`) and stores
``tracked_points.json`` beside the item's results (per frame its points and quality, or the
reason the tracking left it out); each frame is then measured with its own tracked points, and
a frame left out fails with the tracking's reason. The tracking runs whole in that task: every
frame from the first selected one (or the marked one) to the last is read, at most
`settings.tracked_max_span` of them (the frames before the marked one are held until it is
reached); one that still runs out of the task's time limit fails the item saying so. A failed
tracking frees the item's frames from the job's cap.

Frames (`scan_frame`): each frame is measured as a photo of its own (`prismcore.video.frames.frame_spec`)
and gets its own outputs and record; after the item's last frame (`frame_finished`) the item's
result is the summary over its frames: the median of each dimension, with its spread, so a
client sees how repeatable the measurement is.

Uploads (`extract_frame`): the web page shows a frame exactly as the worker will measure it:
decoded by the same code (`prismcore.video.frames`) from the same bytes, whatever the codec. What is
written (keys in `prism_common.upload_keys`): ``{id}.video.json``, the probe (frame count, fps,
size, codec, duration) or ``{"error": ...}`` when the upload is not a video that decodes; the
frame's PNG, or its ``.error.json`` when that frame does not decode. The last video read stays
on local disk (one per process), so a person stepping through frames does not download it again.

Idempotent: decoding is deterministic, so a re-run stores the same frames under the same keys
and sends the same tasks, which count each frame once; an error or a frame already written is
not redone.
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from statistics import median
from typing import Any

import cv2
import numpy as np
from billiard.exceptions import SoftTimeLimitExceeded
from botocore.exceptions import ClientError
from prism_common.queue import TASK_SCAN_FRAME, TASK_SPLIT_VIDEO
from prism_common.records import FINAL_STATES, FrameRecord, ItemResult, ItemView, State
from prism_common.storage import is_missing
from prism_common.upload_keys import frame_error_key, frame_png_key, video_info_key

from prismcore import InputError, ReferencePoints, ScanSpec
from prismcore.io import HEAD_BYTES, iter_frames, load_image, video_container
from prismcore.locate import scan_found
from prismcore.report import FrameInfo
from prismcore.spec import SUMMARY_NAME, TRACKED_NAME
from prismcore.video import (
    FrameSearch,
    PooledFocal,
    Tracking,
    check_points_frame,
    check_points_frame_span,
    focal_estimate,
    frame_info,
    frame_spec,
    pool_focal,
    probe_video,
    select_frames,
    summarize,
    track_video,
    tracked_frame_spec,
    tracked_json,
    tracked_span,
    video_summary,
)

from . import lifecycle
from .artifacts import frame_key, item_key, write_outputs
from .context import WorkerContext
from .inputs import save_input
from .steps import max_pixels

__all__ = ["FOCAL_NAME", "FRAMES_NAME", "POINTS_NAME", "client_message", "extract_frame", "frame_failed",
           "frame_finished", "png_bytes", "scan_frame", "split_video", "track_item"]

log = logging.getLogger(__name__)

FRAMES_NAME = "frames.json"
FOCAL_NAME = "focal.json"  # the focal length pooled over the frames' own fits, when one was
POINTS_NAME = "points.json"  # per frame, points "auto": what the search found, or its reason
_PNG_FAST = [cv2.IMWRITE_PNG_COMPRESSION, 1]  # lossless either way; level 1 is ~5x faster than 3


def png_bytes(rgb: np.ndarray) -> bytes:
    """A decoded frame, RGB uint8 (H, W, 3), as lossless PNG bytes."""
    ok, png = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), _PNG_FAST)
    if not ok:
        raise RuntimeError("a frame could not be encoded as PNG")
    return png.tobytes()


def client_message(exc: InputError, path: Path, name: str) -> str:
    """The engine's message about our local copy at `path`, naming the client's file instead."""
    return str(exc).replace(repr(str(path)), repr(name))


def split_video(ctx: WorkerContext, view: ItemView, part: int = 0) -> None:
    """Select the item's frames, store them and send one scan task per frame.

    A split works for `settings.video_split_part_s` (at most half the task's time limit; its
    download included), then stores where it stopped (the next frame, the point search's
    start, the focal estimates so far: ``split-{part}.json``) and sends `TASK_SPLIT_VIDEO` for
    the next part, so a long video (a search on every frame: about
    0.35 s each) is not cut off by the task's time limit. `part` 0 selects the frames.

    Raises
    ------
    InputError
        Not a video, no frames, indices out of range, more frames than the cap (per video or
        over the job's videos).
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    job_id, item, spec = view.job_id, view.item.index, view.item.spec
    assert spec.frames is not None
    settings = ctx.settings  # a part well inside the task's limit, whatever the operator set
    ends = ctx.clock() + min(settings.video_split_part_s, settings.task_time_limit_s / 2)
    objects = ctx.objects
    if objects.exists(item_key(job_id, item, _split_name(part + 1))):
        if part > 0:
            return  # a repeat of a part that handed on: the next part has the rest
        # The split restarted (the watchdog: the job stalled): a part's task may have been
        # lost with the broker; the split goes on from the last part that handed on.
        part = _last_part(ctx, job_id, item)
    with tempfile.TemporaryDirectory(prefix="prism-video-") as tmp:
        path = Path(tmp) / "video"
        with path.open("wb") as dest:
            label = save_input(ctx, view, "front", dest)
        if part == 0:
            frames = _select(ctx, view, path, label)
            if spec.points_frame is not None:
                try:
                    track_item(ctx, view, path, label, frames)
                except InputError:  # the item fails: its frames no longer count against the job's cap
                    ctx.store.release_frames(job_id, item)
                    raise
            left = _Split(next=0, hint=None, estimates=[], stored=[])
        else:
            frames = _frames(ctx, item_key(job_id, item, FRAMES_NAME))["frames"]
            doc = objects.get_json(item_key(job_id, item, _split_name(part)))
            if doc is None:  # written before this part's task was sent
                raise RuntimeError(f"video split part {part} has no {_split_name(part)}")
            left = _Split(next=doc["next"], hint=None if doc["hint"] is None else tuple(doc["hint"]),
                          estimates=[tuple(e) for e in doc["estimates"]], stored=doc["stored"])
        _split_frames(ctx, view, path, frames, left, part, ends)


def _last_part(ctx: WorkerContext, job_id: str, item: int) -> int:
    """The last part of a split that was handed on (its split-N.json is stored)."""
    part = 1
    while ctx.objects.exists(item_key(job_id, item, _split_name(part + 1))):
        part += 1
    return part


@dataclass
class _Split:
    """Where a split part stopped (``split-{part}.json``): the next frame's position in the
    selection, the point search's start, and (focal pooled) the estimates and frames stored."""

    next: int
    hint: tuple[float, float] | None
    estimates: list[tuple[int, float, float]]  # (frame, focal_px, std_px)
    stored: list[int]


def _split_name(part: int) -> str:
    return f"split-{part}.json"


def _select(ctx: WorkerContext, view: ItemView, path: Path, label: str) -> list[int]:
    """The frames to measure, checked against the caps and recorded (frames.json, the plan)."""
    job_id, item, spec = view.job_id, view.item.index, view.item.spec
    assert spec.frames is not None
    cap, store = ctx.settings.max_frames_per_job, ctx.store
    try:
        info = probe_video(path, max_pixels=max_pixels(ctx, spec.max_pixels))
        check_points_frame(spec, info)
        frames = select_frames(path, spec.frames, info, max_frames=cap)
        if spec.points_frame is not None:
            check_points_frame_span(frames, spec.points_frame, ctx.settings.tracked_max_span)
    except InputError as exc:  # quote the client's name for the video, not our temp file
        raise InputError(client_message(exc, path, label)) from None
    total = store.claim_frames(job_id, item, len(frames))
    if total > cap:
        store.release_frames(job_id, item)
        raise InputError(f"the job's videos select {total} frames, over the cap of {cap} frames "
                         "per job: select fewer (every, start_s/end_s, sharpest or indices)")
    ctx.objects.put_json(item_key(job_id, item, FRAMES_NAME), {"frames": frames, "video": asdict(info)})
    lifecycle.count_plan(ctx, job_id, item, len(frames))  # progress counts frames from here on
    return frames


def track_item(ctx: WorkerContext, view: ItemView, path: Path, label: str, frames: list[int]) -> Tracking:
    """Track the points of `points_frame` to `frames` and store tracked_points.json (unless a
    run before this one did: the tracking is deterministic); the frames tracked and left out.

    Raises
    ------
    InputError
        The points do not fit a box on the marked frame, no frame could be tracked, the span
        is over `settings.tracked_max_span`, or the tracking ran out of the task's time limit
        (what was tracked, and what to do).
    """
    spec, objects = view.item.spec, ctx.objects
    assert spec.points_frame is not None
    key = item_key(view.job_id, view.item.index, TRACKED_NAME)
    try:
        if objects.exists(key):
            doc = objects.get_json(key)
        else:
            try:
                tracked = track_video(spec, path, frames, max_span=ctx.settings.tracked_max_span)
            except SoftTimeLimitExceeded:
                raise InputError(_too_long(ctx, spec.points_frame, frames)) from None
            doc = tracked_json(tracked)
            objects.put_json(key, doc)
        tracking = Tracking.from_json(spec.points_frame, doc)
        tracking.require_some(repr(label))
    except InputError as exc:
        raise InputError(client_message(exc, path, label)) from None
    return tracking


def _too_long(ctx: WorkerContext, points_frame: int, frames: list[int]) -> str:
    """Why an item whose tracking ran out of the task's time limit failed, and what to do."""
    lo, hi = tracked_span(frames, points_frame)
    return (f"tracking the points of frame {points_frame} to the {len(frames)} selected frames (reading "
            f"frames {lo}-{hi}, {hi - lo + 1} frames) took longer than the worker's time limit of "
            f"{ctx.settings.task_time_limit_s:g} s: mark the points on a frame nearer the selected ones "
            "or select frames nearer it (a shorter span), or the operator can lower "
            "PRISM_TRACKED_MAX_SPAN or raise PRISM_TASK_TIME_LIMIT_S")


@lru_cache(maxsize=32)
def _tracking(ctx: WorkerContext, key: str, points_frame: int) -> Tracking:
    """tracked_points.json (never changes once written)."""
    doc = ctx.objects.get_json(key)
    if doc is None:  # the split stores it before any frame's task is sent
        raise RuntimeError(f"the item has no {TRACKED_NAME}")
    return Tracking.from_json(points_frame, doc)


def _tracked_spec(ctx: WorkerContext, view: ItemView, frame: int) -> ScanSpec:
    """The frame's photo spec with its tracked points; InputError with the tracking's reason
    for a frame it left out."""
    spec = view.item.spec
    assert spec.points_frame is not None
    tracking = _tracking(ctx, item_key(view.job_id, view.item.index, TRACKED_NAME), spec.points_frame)
    return tracked_frame_spec(spec, tracking, frame)


def _split_frames(ctx: WorkerContext, view: ItemView, path: Path, frames: list[int], left: _Split,
                  part: int, ends: float) -> None:
    """Store frames[left.next:] (searching each, points "auto") until `ends` (ctx.clock)."""
    job_id, item, spec = view.job_id, view.item.index, view.item.spec
    store, objects = ctx.store, ctx.objects
    # Without a focal length, every frame's own fit is pooled into one (one camera) before any
    # frame is measured: the frames' tasks then wait for the split to end.
    pool = spec.focal_px is None and spec.camera is None and spec.method == "default"
    search = FrameSearch(spec, hint=left.hint) if spec.auto_points is not None else None
    for index, rgb in iter_frames(path, frames[left.next:]):
        if store.state(job_id) != State.running:
            return  # cancelled (or ended) meanwhile: the remaining frames are not wanted
        objects.put_bytes(frame_key(job_id, item, index, "frame.png"), png_bytes(rgb), "image/png")
        photo = _photo_spec(ctx, view, index) if search is None else _search(ctx, view, search, index, rgb)
        if pool:
            if photo is not None and (found := focal_estimate(photo, rgb)) is not None:
                left.estimates.append((index, *found))
            left.stored.append(index)
        else:
            ctx.send_task(TASK_SCAN_FRAME, (job_id, item, index))
        left.next += 1
        if left.next < len(frames) and ctx.clock() >= ends:
            left.hint = None if search is None else search.hint
            objects.put_json(item_key(job_id, item, _split_name(part + 1)), asdict(left))
            # One hand-on per part: a repeat running beside this task (a redelivery) stops at
            # another frame, and two next parts would each run the rest of the video. Its state
            # is written first: either copy's is whole, and a restart finds the part by it.
            if store.claim_split_part(job_id, item, part + 1):
                ctx.send_task(TASK_SPLIT_VIDEO, (job_id, item, part + 1))
            return
    if pool:
        pooled = pool_focal([(f, s) for _, f, s in left.estimates]) if len(left.estimates) >= 2 else None
        if pooled is not None:  # "used": the frames whose estimates were kept
            objects.put_json(item_key(job_id, item, FOCAL_NAME),
                             {"focal_px": pooled.focal_px, "std_px": pooled.std_px,
                              "used": [left.estimates[i][0] for i in pooled.used],
                              "estimates": len(left.estimates)})
        for index in left.stored:
            ctx.send_task(TASK_SCAN_FRAME, (job_id, item, index))


def _photo_spec(ctx: WorkerContext, view: ItemView, index: int) -> ScanSpec | None:
    """The frame's photo spec as the split sees it (None: a frame the tracking left out)."""
    if view.item.spec.points_frame is None:
        return frame_spec(view.item.spec, index)
    try:
        return _tracked_spec(ctx, view, index)
    except InputError:
        return None


def _search(ctx: WorkerContext, view: ItemView, search: FrameSearch, index: int,
            rgb: np.ndarray) -> ScanSpec | None:
    """Find the frame's points (the next frame's search starts from them) and store them, or
    the reason there are none, as points.json; the frame's photo spec, None without points."""
    key = frame_key(view.job_id, view.item.index, index, POINTS_NAME)
    try:
        photo, found = search.resolve(index, rgb)
    except InputError as exc:
        ctx.objects.put_json(key, {"error": str(exc)})
        return None
    assert photo.points is not None
    ctx.objects.put_json(key, {"points": photo.points.model_dump(mode="json"), "side_face": photo.side_face,
                               "found": found.report()})
    return photo


def _frame_spec(ctx: WorkerContext, view: ItemView, frame: int) -> tuple[ScanSpec, dict[str, Any] | None]:
    """The frame's photo spec, and with points "auto" what the search found (points.json).

    Raises InputError with the search's reason for a frame where it found no points.
    """
    spec = view.item.spec
    if spec.points_frame is not None:
        return _tracked_spec(ctx, view, frame), None
    photo = frame_spec(spec, frame)
    if spec.auto_points is None:
        return photo, None
    doc = ctx.objects.get_json(frame_key(view.job_id, view.item.index, frame, POINTS_NAME))
    if doc is None:  # the split stores it before the frame's task is sent
        raise RuntimeError(f"frame {frame} has no {POINTS_NAME}")
    if "error" in doc:
        raise InputError(doc["error"])
    points = ReferencePoints.model_validate(doc["points"])
    return photo.model_copy(update={"points": points, "side_face": doc["side_face"],
                                    "auto_points": None}), doc["found"]


def scan_frame(ctx: WorkerContext, view: ItemView, frame: int) -> None:
    """Measure the frame and record it: its outputs, or the error that stopped it."""
    job_id, item, spec = view.job_id, view.item.index, view.item.spec
    try:
        photo_spec, auto = _frame_spec(ctx, view, frame)
        data = ctx.objects.get_bytes(frame_key(job_id, item, frame, "frame.png"))
        image = load_image(data, max_pixels=max_pixels(ctx, spec.max_pixels), name=f"frame {frame}")
        pooled = _pooled(ctx, item_key(job_id, item, FOCAL_NAME))
        scan = scan_found(photo_spec, auto, image, pooled_focal=pooled)
        fps = _frames(ctx, item_key(job_id, item, FRAMES_NAME))["video"]["fps"]
        # as the CLI's per-frame report says
        scan.report.frame = FrameInfo.model_validate(frame_info(frame, fps))
        result, outputs = write_outputs(ctx, job_id, item, photo_spec, scan, [image], frame=frame)
    except InputError as exc:
        record = FrameRecord(index=frame, state=State.failed, error=str(exc))
    else:
        record = FrameRecord(index=frame, state=State.succeeded, result=result, outputs=outputs)
    ctx.store.put_frame(job_id, item, record)


def frame_failed(ctx: WorkerContext, job_id: str, item: int, frame: int, message: str) -> None:
    """Record a frame whose task failed for good (unless it has a record already)."""
    store = ctx.store
    if not store.get_frames(job_id, item, [frame]):
        store.put_frame(job_id, item, FrameRecord(index=frame, state=State.failed, error=message))


def frame_finished(ctx: WorkerContext, job_id: str, item: int, frame: int, *, maybe_repeat: bool) -> None:
    """Count the frame; after the item's last frame, summarise the item and complete it."""
    done = ctx.store.frame_done(job_id, item, frame)
    frames = _frames(ctx, item_key(job_id, item, FRAMES_NAME))
    if done >= len(frames["frames"]):
        _finish_video(ctx, job_id, item, frames, maybe_repeat=maybe_repeat)


@lru_cache(maxsize=32)
def _pooled(ctx: WorkerContext, key: str) -> PooledFocal | None:
    """focal.json: the focal length pooled over the video's frames (None: none was pooled);
    its `used` are frame indices (the frames whose estimates were kept)."""
    objects = ctx.objects
    if not objects.exists(key):
        return None
    doc = objects.get_json(key)
    return PooledFocal(doc["focal_px"], doc["std_px"], tuple(doc["used"]))


@lru_cache(maxsize=32)
def _frames(ctx: WorkerContext, key: str) -> dict[str, Any]:
    """frames.json (never changes once written)."""
    doc: dict[str, Any] = json.loads(ctx.objects.get_bytes(key))
    return doc  # missing: an error, retried


def _finish_video(ctx: WorkerContext, job_id: str, item: int, frames: dict[str, Any], *,
                  maybe_repeat: bool) -> None:
    store = ctx.store
    view = store.get_item(job_id, item)
    if view is None or view.state != State.running:
        return
    if view.item.state not in FINAL_STATES:  # else a repeat: only complete it
        records = store.get_frames(job_id, item, frames["frames"])
        per_frame = {n: {"dimensions": r.result.dimensions} if r.result else {"error": r.error}
                     for n, r in records.items()}
        measured = [r.result for r in records.values() if r.result is not None]
        if not measured:
            first = summarize(per_frame)["failed"][0]
            lifecycle.fail_item(ctx, job_id, item, f"no frame could be measured (frame {first['frame']}: "
                                           f"{first['error']})")
        else:
            selection = view.item.spec.frames
            assert selection is not None  # a video item's spec has one
            pooled = _pooled(ctx, item_key(job_id, item, FOCAL_NAME))
            outputs: dict[str, str] = {}
            warnings: list[str] = []
            extra: dict[str, Any] = {}
            if (points_frame := view.item.spec.points_frame) is not None:
                outputs["tracked_points"] = tracked = item_key(job_id, item, TRACKED_NAME)
                tracking = _tracking(ctx, tracked, points_frame)
                extra["tracking"] = tracking.block()
                warnings += tracking.warnings()
            # The same document as the CLI's summary.json; the video named by its reference.
            summary = video_summary(per_frame, fps=frames["video"]["fps"] or None,
                                    video={"reference": view.item.spec.image, **frames["video"]},
                                    selection=selection, pooled=pooled,
                                    pooled_frames=pooled.used if pooled else (), extra=extra)
            key = item_key(job_id, item, SUMMARY_NAME)
            ctx.objects.put_json(key, summary)
            dims = {k: v["median"] for k, v in summary["dimensions"].items()}
            failed = summary["frames"]["failed"]
            if failed:
                warnings.insert(0, f"{failed} of {len(records)} frames could not be measured")
            result = ItemResult(points=sum(r.points for r in measured),
                                dimensions={**dims, "unit": summary["unit"]},
                                point_loss=median(r.point_loss for r in measured),
                                warnings=warnings, summary=summary)
            lifecycle.succeed_item(ctx, job_id, view.item, result, {"summary": key, **outputs})
    lifecycle.complete_item(ctx, job_id, item, maybe_repeat=maybe_repeat)


# -- an uploaded video's frames, for a person to mark ------------------------------------------
_CHUNK = 1 << 20
_local: dict[str, Path] = {}  # upload id -> its file, at most one entry
_folder: tempfile.TemporaryDirectory[str] | None = None  # removed when the process exits


def extract_frame(ctx: WorkerContext, upload_id: str, frame: int) -> None:
    """Probe the upload (unless done) and store frame `frame` as a PNG (unless done or out of
    range). A file that is not a decodable video gets its error recorded, never raised."""
    written = _extract(ctx, upload_id, frame)
    if written and ctx.store.get_upload(upload_id) is None:
        # The upload expired while this ran: its sweep has gone by, so leave nothing behind.
        ctx.objects.delete_keys(written)


def _extract(ctx: WorkerContext, upload_id: str, frame: int) -> list[str]:
    """What `extract_frame` does; returns the keys it wrote."""
    written: list[str] = []
    upload = ctx.store.get_upload(upload_id)
    if upload is None or frame < 0:
        log.warning("no frame %s of upload %s to extract", frame, upload_id)
        return written
    tenant, name = upload["tenant"], upload.get("name") or upload_id
    objects = ctx.objects
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
        path = _local_copy(ctx, upload_id, upload["key"])
    except ClientError as exc:
        if not is_missing(exc):
            raise  # the store's trouble: retried
        # The record outlived the file (deleted by hand, or expiring): say so, once, for good.
        objects.put_json(info_key, {"error": f"{name!r} is no longer stored: upload it again"})
        return [info_key]
    if info is None:
        try:
            info = asdict(probe_video(path, max_pixels=ctx.settings.max_pixels))
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


def _local_copy(ctx: WorkerContext, upload_id: str, key: str) -> Path:
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
    objects = ctx.objects
    with objects.client.get_object(Bucket=objects.bucket, Key=key)["Body"] as body, partial.open("wb") as f:
        shutil.copyfileobj(body, f, _CHUNK)
    partial.replace(path)  # a fetch cut short never passes for the whole file
    _local[upload_id] = path
    return path

"""Measure one frame of a video item, and finish the item when its last frame is done.

Each frame is measured as a photo of its own (`prismcore.video.frame_spec`) and gets its own
outputs and record; the item's result is the summary over its frames: the median of each
dimension, with its spread, so a client sees how repeatable the measurement is.
"""

from __future__ import annotations

import json
from functools import lru_cache
from statistics import median

from prism_common.records import FINAL_STATES, FrameRecord, ItemResult, ItemView, State

from prismcore import InputError, run_scan
from prismcore.images import load_image
from prismcore.pooling import PooledFocal
from prismcore.spec import SUMMARY_NAME
from prismcore.summary import frame_info, summarize
from prismcore.video import frame_spec

from . import context, fanout
from .keys import frame_key, item_key
from .outputs import write_outputs
from .planning import max_pixels
from .video_item import FOCAL_NAME, FRAMES_NAME

__all__ = ["frame_failed", "frame_finished", "scan_frame"]


def scan_frame(view: ItemView, frame: int) -> None:
    """Measure the frame and record it: its outputs, or the error that stopped it."""
    job_id, item, spec = view.job_id, view.item.index, view.item.spec
    try:
        photo_spec = frame_spec(spec, frame)
        data = context.objects().get_bytes(frame_key(job_id, item, frame, "frame.png"))
        image = load_image(data, max_pixels=max_pixels(spec.max_pixels), name=f"frame {frame}")
        scan = run_scan(photo_spec, image, pooled_focal=_pooled(item_key(job_id, item, FOCAL_NAME)))
        fps = _frames(item_key(job_id, item, FRAMES_NAME))["video"]["fps"]
        scan.report["frame"] = frame_info(frame, fps)  # as the CLI's per-frame report says
        result, outputs = write_outputs(job_id, item, photo_spec, scan, [image], frame=frame)
    except InputError as exc:
        record = FrameRecord(index=frame, state=State.failed, error=str(exc))
    else:
        record = FrameRecord(index=frame, state=State.succeeded, result=result, outputs=outputs)
    context.store().put_frame(job_id, item, record)


def frame_failed(job_id: str, item: int, frame: int, message: str) -> None:
    """Record a frame whose task failed for good (unless it has a record already)."""
    store = context.store()
    if not store.get_frames(job_id, item, [frame]):
        store.put_frame(job_id, item, FrameRecord(index=frame, state=State.failed, error=message))


def frame_finished(job_id: str, item: int, frame: int, *, maybe_repeat: bool) -> None:
    """Count the frame; after the item's last frame, summarise the item and complete it."""
    done = context.store().frame_done(job_id, item, frame)
    frames = _frames(item_key(job_id, item, FRAMES_NAME))
    if done >= len(frames["frames"]):
        _finish_video(job_id, item, frames, maybe_repeat=maybe_repeat)


@lru_cache(maxsize=32)
def _pooled(key: str) -> PooledFocal | None:
    """focal.json: the focal length pooled over the video's frames (None: none was pooled)."""
    objects = context.objects()
    if not objects.exists(key):
        return None
    doc = objects.get_json(key)
    return PooledFocal(doc["focal_px"], doc["std_px"], tuple(doc["used"]))


@lru_cache(maxsize=32)
def _frames(key: str) -> dict:
    """frames.json (never changes once written)."""
    return json.loads(context.objects().get_bytes(key))  # missing: an error, retried


def _finish_video(job_id: str, item: int, frames: dict, *, maybe_repeat: bool) -> None:
    store = context.store()
    view = store.get_item(job_id, item)
    if view is None or view.state != State.running:
        return
    if view.item.state not in FINAL_STATES:  # else a repeat: only complete it
        records = store.get_frames(job_id, item, frames["frames"])
        summary = summarize({n: {"dimensions": r.result.dimensions} if r.result else {"error": r.error}
                             for n, r in records.items()}, fps=frames["video"]["fps"] or None)
        measured = [r.result for r in records.values() if r.result is not None]
        if not measured:
            first = summary["failed"][0]
            fanout.fail_item(job_id, item, f"no frame could be measured (frame {first['frame']}: "
                                           f"{first['error']})")
        else:
            # The same document as the CLI's summary.json; the video named by its reference.
            summary["video"] = {"reference": view.item.spec.image, **frames["video"]}
            summary["selection"] = view.item.spec.frames.model_dump(mode="json", exclude_none=True)
            if (pooled := _pooled(item_key(job_id, item, FOCAL_NAME))) is not None:
                summary["focal"] = {"pooled_px": round(pooled.focal_px, 3), "std_px": round(pooled.std_px, 3),
                                    "frames": [frames["frames"][i] for i in pooled.used]}
            key = item_key(job_id, item, SUMMARY_NAME)
            context.objects().put_json(key, summary)
            dims = {k: v["median"] for k, v in summary["dimensions"].items()}
            failed = summary["frames"]["failed"]
            warnings = [f"{failed} of {len(records)} frames could not be measured"] if failed else []
            result = ItemResult(points=sum(r.points for r in measured),
                                dimensions={**dims, "unit": summary["unit"]},
                                point_loss=median(r.point_loss for r in measured),
                                warnings=warnings, summary=summary)
            fanout.succeed_item(job_id, view.item, result, {"summary": key})
    fanout.complete_item(job_id, item, maybe_repeat=maybe_repeat)

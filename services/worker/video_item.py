"""Split a video item into its frames: read the video once, select the frames, store each one as
a lossless PNG and send its scan task as soon as it is stored, so frames are measured while the
split goes on. One decoded frame is in memory at a time.

Idempotent: decoding is deterministic, so a re-run stores the same frames under the same keys
and sends the same tasks, which count each frame once.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np
from prism_common.queue import TASK_SCAN_FRAME
from prism_common.records import ItemView, State

from prismcore import InputError
from prismcore.pooling import focal_estimate, pool_focal
from prismcore.video import frame_spec, iter_frames, probe_video, select_frames

from . import context
from .app import app
from .fanout import count_plan
from .inputs import save_input
from .keys import frame_key, item_key
from .planning import max_pixels

__all__ = ["FOCAL_NAME", "FRAMES_NAME", "client_message", "png_bytes", "split_video"]

FRAMES_NAME = "frames.json"
FOCAL_NAME = "focal.json"  # the focal length pooled over the frames' own fits, when one was
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


def split_video(view: ItemView) -> list[int]:
    """Select the item's frames, store them and send one scan task per frame; the frames.

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
    cap, store, objects = context.settings().max_frames_per_job, context.store(), context.objects()
    with tempfile.TemporaryDirectory(prefix="prism-video-") as tmp:
        path = Path(tmp) / "video"
        with path.open("wb") as dest:
            label = save_input(view, "front", dest)
        try:
            info = probe_video(path, max_pixels=max_pixels(spec.max_pixels))
            frames = select_frames(path, spec.frames, info, max_frames=cap)
        except InputError as exc:  # quote the client's name for the video, not our temp file
            raise InputError(client_message(exc, path, label)) from None
        total = store.claim_frames(job_id, item, len(frames))
        if total > cap:
            store.release_frames(job_id, item)
            raise InputError(f"the job's videos select {total} frames, over the cap of {cap} frames "
                             "per job: select fewer (every, start_s/end_s, sharpest or indices)")
        objects.put_json(item_key(job_id, item, FRAMES_NAME), {"frames": frames, "video": asdict(info)})
        count_plan(job_id, item, len(frames))  # progress counts frames from here on
        # Without a focal length, every frame's own fit is pooled into one (one camera) before
        # any frame is measured: the frames' tasks then wait for the split to end.
        pool = spec.focal_px is None and spec.camera is None and spec.method == "default"
        estimates: list[tuple[float, float]] = []
        stored: list[int] = []
        for index, rgb in iter_frames(path, frames):
            if store.state(job_id) != State.running:
                break  # cancelled (or ended) meanwhile: the remaining frames are not wanted
            objects.put_bytes(frame_key(job_id, item, index, "frame.png"), png_bytes(rgb), "image/png")
            if pool:
                if (found := focal_estimate(frame_spec(spec, index), rgb)) is not None:
                    estimates.append(found)
                stored.append(index)
            else:
                app.send_task(TASK_SCAN_FRAME, (job_id, item, index))
        if pool:
            pooled = pool_focal(estimates) if len(estimates) >= 2 else None
            if pooled is not None:
                objects.put_json(item_key(job_id, item, FOCAL_NAME),
                                 {"focal_px": pooled.focal_px, "std_px": pooled.std_px,
                                  "used": list(pooled.used), "estimates": len(estimates)})
            for index in stored:
                app.send_task(TASK_SCAN_FRAME, (job_id, item, index))
    return frames

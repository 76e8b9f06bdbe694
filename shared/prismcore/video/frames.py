"""Videos in the engine: every selected frame of a video is measured as a photo of its own.

The public names for callers (CLI, worker) live here: `probe_video` checks a file and reads its
size, rate and codec; `select_frames` turns a spec's `FrameSelection` into frame indices under a
cap; `iter_frames` streams those frames as RGB arrays; `frame_spec` gives each frame's photo
spec, which runs through `run_scan` (or `plan_scan` and the tiles) unchanged.
"""

from __future__ import annotations

from prismcore.errors import InputError
from prismcore.io.video_decode import SEEK_GAP, VideoInfo, is_video, iter_frames, probe_video
from prismcore.spec import ScanSpec
from prismcore.video.frame_select import DEFAULT_MAX_FRAMES, frame_sharpness, select_frames

__all__ = [
    "DEFAULT_MAX_FRAMES",
    "SEEK_GAP",
    "VideoInfo",
    "frame_sharpness",
    "frame_spec",
    "is_video",
    "iter_frames",
    "probe_video",
    "select_frames",
]


def frame_spec(spec: ScanSpec, index: int) -> ScanSpec:
    """The photo spec of one frame of a video spec: its reference points, without `frames`.

    Each frame then goes through `run_scan` / `plan_scan` like any photo. The result's report
    echoes this spec (its `image` is still the video's reference); callers add the frame index.

    Raises
    ------
    ValueError
        `spec` is not a video spec (it has no `frames`).
    InputError
        `spec` has per-frame points and none for `index`.
    """
    if spec.frames is None:
        raise ValueError("frame_spec needs a video spec (one with frames)")
    if spec.frame_points is not None:
        points = spec.frame_points.get(index)
        if points is None:
            raise InputError(f"frame {index} has no reference points in frame_points "
                             f"(it gives frames {sorted(spec.frame_points)})")
    else:
        points = spec.points
    data = spec.model_dump(exclude={"frames", "frame_points", "points", "fit", "points_frame"})
    return ScanSpec.model_validate({**data, "points": points.model_dump() if points else None})

"""Videos: which frames to measure, the zero-click search along them, one focal length pooled
over a camera's frames, and the summary of a video's measurements.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "FrameSearch",
    "PooledFocal",
    "focal_estimate",
    "frame_spec",
    "pool_focal",
    "probe_video",
    "select_frames",
    "summarize",
    "track_points",
]

_EXPORTS = {
    "FrameSearch": "point_search",
    "PooledFocal": "pooling",
    "focal_estimate": "pooling",
    "frame_spec": "frames",
    "pool_focal": "pooling",
    "probe_video": "frames",
    "select_frames": "frames",
    "summarize": "summary",
    "track_points": "tracking",
}

if TYPE_CHECKING:
    from prismcore.video.frames import frame_spec, probe_video, select_frames
    from prismcore.video.point_search import FrameSearch
    from prismcore.video.pooling import PooledFocal, focal_estimate, pool_focal
    from prismcore.video.summary import summarize
    from prismcore.video.tracking import track_points

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

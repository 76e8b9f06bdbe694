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
    "box_refiner",
    "focal_estimate",
    "frame_spec",
    "pool_focal",
    "probe_video",
    "select_frames",
    "summarize",
    "track_points",
    "viewing_spread",
]

_EXPORTS = {
    "FrameSearch": "point_search",
    "box_refiner": "track_refine",
    "PooledFocal": "pooling",
    "focal_estimate": "pooling",
    "frame_spec": "frames",
    "pool_focal": "pooling",
    "probe_video": "frames",
    "select_frames": "frames",
    "summarize": "summary",
    "track_points": "tracking",
    "viewing_spread": "frame_select",
}

if TYPE_CHECKING:
    from prismcore.video.frame_select import viewing_spread
    from prismcore.video.frames import frame_spec, probe_video, select_frames
    from prismcore.video.point_search import FrameSearch
    from prismcore.video.pooling import PooledFocal, focal_estimate, pool_focal
    from prismcore.video.summary import summarize
    from prismcore.video.track_refine import box_refiner
    from prismcore.video.tracking import track_points

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

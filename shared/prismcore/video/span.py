"""The span of frames a tracking from a marked frame reads, and the words when it is too long or
the marked frame is past the video's end: plain Python, so the API checks a job with them without
loading the engine (numpy, OpenCV, SciPy belong to the workers)."""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["TRACKED_MAX_SPAN", "points_frame_problem", "span_problem", "tracked_span"]

TRACKED_MAX_SPAN = 300
"""The most frames one tracking reads (`tracked_span`; the service's ``PRISM_TRACKED_MAX_SPAN``).
The tracker holds every frame before the marked one, grey at full size, until it reaches it:
300 frames of 1920x1080 are 620 MB (8.3 MB a frame at 3840x2160: lower the cap for such videos).
Time is not what bounds it: reading and tracking a 1920x1080 MJPEG frame cost 28 ms of CPU (one
thread, 60 frames, the marked one last), 8.4 s for 300, well inside a worker task's 240 s."""


def points_frame_problem(points_frame: int | None, frame_count: int) -> str | None:
    """Why `points_frame` is not one of a video's `frame_count` frames, or None (also for none)."""
    if points_frame is not None and frame_count and points_frame >= frame_count:
        return (f"points_frame {points_frame} is past the video's end: it has {frame_count} frames "
                f"(0-{frame_count - 1})")
    return None


def tracked_span(frames: Iterable[int], points_frame: int) -> tuple[int, int]:
    """The first and last frame a tracking from `points_frame` to `frames` reads (every frame
    between them is decoded)."""
    every = [*frames, points_frame]
    return min(every), max(every)


def span_problem(frames: Iterable[int], points_frame: int, max_span: int) -> str | None:
    """Why tracking from `points_frame` to `frames` is refused (it reads more than `max_span`
    frames), or None."""
    lo, hi = tracked_span(frames, points_frame)
    if hi - lo + 1 <= max_span:
        return None
    return (f"points_frame {points_frame}: tracking the points to the selected frames reads frames "
            f"{lo}-{hi}, {hi - lo + 1} frames, over the cap of {max_span} frames one tracking may "
            "read: mark the points on a frame nearer the selected ones, or select frames nearer "
            f"frame {points_frame} (start_s/end_s or indices)")

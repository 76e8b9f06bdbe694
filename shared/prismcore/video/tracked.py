"""A video whose seven points are marked on one frame (`ScanSpec.points_frame`): the steps `prism
scan VIDEO --points ... --points-frame N` and the worker share, between reading the file and
writing the results.

* `check_points_frame`: the marked frame must be one of the video's;
* `track_video`: the marked points carried to the selected frames by
  `prismcore.video.tracking.track_points`, every frame between them read, the selected ones
  refined on the box's edges by the plan the measurement itself makes (`refine_fields`: the
  fields of the frame's own photo spec, `prismcore.video.frames.frame_spec`);
* `tracked_json`: tracked_points.json's content (per frame, its points and quality or the
  reason it is left out); `Tracking`: the frames tracked and those left out, and the
  ``tracking`` block both summaries carry;
* `per_frame_spec`: the spec that measures each tracked frame as a photo with its own points
  (``frame_points``), frame by frame through `frame_spec` as any video with frame_points is;
* `joint_frames`: the tracked frames a joint fit takes (the views that differ most, under the
  pixels one fit may hold), then `fit_tracked` measures them as ONE box.

Decoding goes through `prismcore.io.video_decode` (a path in, RGB arrays out); nothing is
written here: the callers store tracked_points.json and the reports where they keep results.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from prismcore.errors import InputError
from prismcore.io.video_decode import VideoInfo, iter_frames
from prismcore.multiview.joint import JointResult, View, fit_views
from prismcore.spec import JOINT_MAX_PIXELS, TRACKED_NAME, KnownEdge, ScanSpec
from prismcore.video.frame_select import viewing_spread
from prismcore.video.frames import frame_spec
from prismcore.video.span import TRACKED_MAX_SPAN, points_frame_problem, span_problem, tracked_span
from prismcore.video.track_refine import box_refiner
from prismcore.video.tracking import TrackedFrame, to_reference, track_points

__all__ = [
    "JOINT_TRACKED_VIEWS",
    "TRACKED_MAX_SPAN",
    "TRACKED_NAME",
    "Tracking",
    "check_points_frame",
    "check_points_frame_span",
    "fit_tracked",
    "joint_frames",
    "left_out_message",
    "per_frame_spec",
    "points_frame_problem",
    "refine_fields",
    "span_problem",
    "track_video",
    "tracked_frame_spec",
    "tracked_json",
    "tracked_span",
    "tracked_views",
]

JOINT_TRACKED_VIEWS = 30
"""The most tracked frames one joint fit takes (those whose views differ most)."""

_NOT_PHOTO = {"image", "points", "formats"}  # what box_refiner sets itself


def check_points_frame(spec: ScanSpec, info: VideoInfo) -> None:
    """Raise InputError when `spec.points_frame` is past the video's last frame (`info`: its probe)."""
    if (problem := points_frame_problem(spec.points_frame, info.frame_count)) is not None:
        raise InputError(problem)


def check_points_frame_span(frames: Iterable[int], points_frame: int, max_span: int) -> None:
    """Raise InputError (`span_problem`'s words) when the tracking would read over `max_span` frames."""
    if (problem := span_problem(frames, points_frame, max_span)) is not None:
        raise InputError(problem)


def refine_fields(spec: ScanSpec) -> dict[str, Any]:
    """The photo-spec fields the tracker's refinement plans with: those of the marked frame's own
    photo spec (`frame_spec`, the one each frame is measured with), less its image and points,
    so the refinement plans exactly as the measurement will (side face, focal length, camera,
    scale, region, hint, pixel cap...)."""
    if spec.points_frame is None:
        raise ValueError("refine_fields needs a spec with points_frame")
    photo = frame_spec(spec, spec.points_frame)
    return photo.model_dump(mode="json", exclude=_NOT_PHOTO, exclude_none=True)


def track_video(spec: ScanSpec, path: Path | str, indices: Iterable[int], *,
                max_span: int = TRACKED_MAX_SPAN) -> dict[int, TrackedFrame]:
    """Track `spec.points` (marked on frame `spec.points_frame`) through the video at `path` to
    the frames `indices`: every frame from the first of them (or the marked one) to the last is
    decoded, one at a time; at most `max_span` frames (`check_points_frame_span`), as the frames
    before the marked one are held until it is reached.

    Returns
    -------
    dict of int to TrackedFrame
        Per frame of `indices` the video held: its points (7, 2) px and quality, or the reason
        it is left out.

    Raises
    ------
    InputError
        The points describe no box, do not fit one on the marked frame, the span is over
        `max_span`, or the video does not decode as far as the marked frame.
    """
    if spec.points is None or spec.points_frame is None:
        raise ValueError("track_video needs a spec with points and points_frame")
    wanted = sorted(set(indices))
    start = spec.points_frame
    check_points_frame_span(wanted, start, max_span)
    lo, hi = tracked_span(wanted, start)
    frames = iter_frames(path, range(lo, hi + 1))
    try:
        return track_points(frames, spec.points, start, report=set(wanted), side_face=spec.side_face,
                            refine=box_refiner(refine_fields(spec)))
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()


def tracked_json(tracked: dict[int, TrackedFrame]) -> dict[str, Any]:
    """tracked_points.json: ``{"<frame>": {"points": [[x, y] x 7], "quality": {...}}}``, or
    ``{"reason": ...}`` for a frame left out; frames in increasing order."""
    return {str(index): frame.as_json() for index, frame in sorted(tracked.items())}


def left_out_message(index: int, reason: str | None) -> str:
    """How a frame the tracking left out is named (a frame's error, a warning)."""
    return f"frame {index} left out by the tracking: {reason or 'no reason given'}"


@dataclass(frozen=True)
class Tracking:
    """The tracked frames of a video: `good` frame -> points (7, 2) px, `left` frame -> reason."""

    points_frame: int
    good: dict[int, np.ndarray]
    left: dict[int, str | None]

    @classmethod
    def of(cls, points_frame: int, tracked: dict[int, TrackedFrame]) -> Tracking:
        return cls(points_frame,
                   {i: f.points for i, f in sorted(tracked.items()) if f.points is not None},
                   {i: f.reason for i, f in sorted(tracked.items()) if f.points is None})

    @classmethod
    def from_json(cls, points_frame: int, doc: dict[str, Any]) -> Tracking:
        """From tracked_points.json's content (`tracked_json`)."""
        good = {int(k): np.asarray(v["points"], dtype=np.float64) for k, v in doc.items() if "points" in v}
        left = {int(k): v.get("reason") for k, v in doc.items() if "points" not in v}
        return cls(points_frame, dict(sorted(good.items())), dict(sorted(left.items())))

    def require_some(self, what: str) -> None:
        """InputError when no frame was tracked (naming the first reason)."""
        if not self.good:
            first = next(iter(self.left.values()), None)
            raise InputError(f"no frame of {what} could be tracked from frame {self.points_frame}"
                             + (f": {first}" if first else ""))

    def block(self, chosen: list[int] | None = None) -> dict[str, Any]:
        """The ``tracking`` block of summary.json and joint.json."""
        out: dict[str, Any] = {"points_frame": self.points_frame, "tracked": sorted(self.good),
                               "left_out": {str(i): r for i, r in sorted(self.left.items())}}
        if chosen is not None:
            out["chosen"] = list(chosen)
        return out

    def warnings(self) -> list[str]:
        """One per frame left out, with its reason."""
        return [left_out_message(i, r) for i, r in sorted(self.left.items())]


def per_frame_spec(spec: ScanSpec, tracking: Tracking) -> ScanSpec:
    """The video spec that measures each tracked frame one by one with its own points:
    ``frame_points`` the tracked points (frames left out have none; the spec's frames are then
    the tracked ones); `frame_spec(result, i)` is frame i's photo spec (`tracked_frame_spec`
    gives it without building the whole)."""
    return _with_points(spec, tracking.good)


def tracked_frame_spec(spec: ScanSpec, tracking: Tracking, frame: int) -> ScanSpec:
    """Frame `frame`'s photo spec with its tracked points: ``frame_spec(per_frame_spec(spec,
    tracking), frame)``, built from that frame's points alone (the whole per-frame spec costs
    time in proportion to the frames tracked, per frame measured).

    Raises
    ------
    InputError
        The tracking left `frame` out (its reason), or did not track it.
    """
    if frame not in tracking.good:
        raise InputError(left_out_message(frame, tracking.left.get(frame, "not among the frames tracked")))
    return frame_spec(_with_points(spec, {frame: tracking.good[frame]}), frame)


def _with_points(spec: ScanSpec, good: dict[int, np.ndarray]) -> ScanSpec:
    data = spec.model_dump(mode="json", exclude={"points", "points_frame", "frames", "fit", "frame_points"})
    data["frame_points"] = {str(i): to_reference(p).model_dump(mode="json") for i, p in good.items()}
    return ScanSpec.model_validate(data)


def joint_frames(tracking: Tracking, info: VideoInfo) -> list[int]:
    """The tracked frames a joint fit takes: those whose views differ most
    (`frame_select.viewing_spread`), at most `JOINT_TRACKED_VIEWS` and as many as
    `JOINT_MAX_PIXELS` lets be held decoded at once (the fit holds every view)."""
    fit_at_once = max(2, JOINT_MAX_PIXELS // max(1, info.width * info.height))
    return viewing_spread(tracking.good, min(JOINT_TRACKED_VIEWS, fit_at_once))


def fit_tracked(spec: ScanSpec, frames: Iterable[tuple[int, np.ndarray]], tracking: Tracking) -> JointResult:
    """The tracked frames `frames` ((index, RGB (H, W, 3) uint8), those of `joint_frames`)
    measured as ONE box with their tracked points.

    Raises
    ------
    InputError
        The spec's scale is not a known edge, or no view can be measured.
    """
    if not isinstance(spec.scale, KnownEdge):
        raise InputError('fit "joint" needs a known edge as the scale (scale kind "edge")')
    return fit_views(tracked_views(spec, frames, tracking), spec.scale, focal_px=spec.focal_px)


def tracked_views(spec: ScanSpec, frames: Iterable[tuple[int, np.ndarray]], tracking: Tracking) -> list[View]:
    """The tracked frames `frames` ((index, RGB (H, W, 3) uint8)) as a joint fit's views, each
    with its tracked points, named "frame N"."""
    return [View(image, tracking.good[index].tolist(), spec.side_face, f"frame {index}")
            for index, image in frames]

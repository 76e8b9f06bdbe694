"""`prism scan VIDEO --points "..." --points-frame N`: points marked on one frame, tracked to the others.

The seven points marked on frame N are carried to every selected frame by
`prismcore.video.tracking.track_points` (every frame between the selected ones is tracked, the
selected ones refined on the box's edges by the engine's own plan); each selected frame's points,
or the reason it is left out, go to ``tracked_points.json`` in the output folder. The tracked
frames are then measured one by one as `prism scan VIDEO` measures a video with `frame_points`
(a folder per frame, summary.json), or with fit "joint" as ONE box over the frames whose views
differ most (`frame_select.viewing_spread`, up to `JOINT_TRACKED_VIEWS`): joint.json.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.markup import escape

from prismcore.errors import InputError
from prismcore.io.video_decode import iter_frames, probe_video
from prismcore.multiview.joint import View, fit_views
from prismcore.multiview.report import joint_report
from prismcore.spec import JOINT_MAX_PIXELS, SUMMARY_NAME, KnownEdge, ScanSpec
from prismcore.video.frame_select import select_frames, viewing_spread
from prismcore.video.track_refine import box_refiner
from prismcore.video.tracking import TrackedFrame, to_reference, track_points

__all__ = ["JOINT_TRACKED_VIEWS", "TRACKED_NAME", "scan_tracked", "track_video"]

console = Console()

TRACKED_NAME = "tracked_points.json"
JOINT_TRACKED_VIEWS = 30
"""The most tracked frames one joint fit takes (those whose views differ most)."""


def track_video(spec: ScanSpec, path: Path, indices: list[int]) -> dict[int, TrackedFrame]:
    """Track `spec.points` (on frame `spec.points_frame`) through the video at `path` to the
    frames `indices`; every frame from the first to the last of them (and the marked one) is read."""
    assert spec.points is not None and spec.points_frame is not None
    start = spec.points_frame
    lo, hi = min([*indices, start]), max([*indices, start])
    extra: dict[str, Any] = {"side_face": spec.side_face}
    if spec.focal_px is not None:
        extra["focal_px"] = spec.focal_px
    if spec.camera is not None:
        extra["camera"] = spec.camera.model_dump(mode="json")
    frames: Iterator[tuple[int, np.ndarray]] = iter_frames(path, range(lo, hi + 1))
    try:
        return track_points(frames, spec.points, start, report=set(indices), side_face=spec.side_face,
                            refine=box_refiner(extra))
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()


def tracked_json(tracked: dict[int, TrackedFrame]) -> dict[str, Any]:
    """tracked_points.json: per frame index, its points and quality, or the reason it is left out."""
    return {str(index): frame.as_json() for index, frame in sorted(tracked.items())}


def scan_tracked(spec: ScanSpec, base: Path, out: Path, *, tiles: int, max_frames: int) -> dict[str, Any]:
    """Track the points of `spec` (`points_frame`) and measure the tracked frames; returns the
    summary (frames one by one) or the joint report (fit "joint").

    Raises
    ------
    InputError
        Not a video, the marked frame past the video's end, or no frame tracked or measured.
    """
    assert spec.frames is not None and spec.points_frame is not None
    path = base / spec.image
    info = probe_video(path, max_pixels=spec.max_pixels)
    if info.frame_count and spec.points_frame >= info.frame_count:
        raise InputError(f"points_frame {spec.points_frame} is past the video's end: it has "
                         f"{info.frame_count} frames (0-{info.frame_count - 1})")
    indices = select_frames(path, spec.frames, info, max_frames=max_frames)
    console.print(f"{path}: {info.width}x{info.height}, {info.frame_count} frames; tracking the points of "
                  f"frame {spec.points_frame} to {len(indices)} selected frames")
    tick = time.process_time()
    tracked = track_video(spec, path, indices)
    cpu_s = time.process_time() - tick
    out.mkdir(parents=True, exist_ok=True)
    (out / TRACKED_NAME).write_text(json.dumps(tracked_json(tracked), indent=1) + "\n")
    good = {i: f.points for i, f in tracked.items() if f.points is not None}
    left = {i: f.reason for i, f in tracked.items() if f.points is None}
    console.print(f"tracked {len(good)} of {len(tracked)} frames ({cpu_s:.1f} s CPU); points: "
                  f"{out / TRACKED_NAME}")
    for index, reason in sorted(left.items()):
        console.print(f"[yellow]frame {index} left out:[/] {escape(str(reason))}", soft_wrap=True)
    if not good:
        raise InputError(f"no frame of {str(path)!r} could be tracked from frame {spec.points_frame}"
                         + (f": {next(iter(left.values()))}" if left else ""))
    if spec.fit == "joint":
        return _joint(spec, path, out, good, left)
    return _frames(spec, base, out, tiles, max_frames, good, left)


def _frames(spec: ScanSpec, base: Path, out: Path, tiles: int, max_frames: int,
            good: dict[int, np.ndarray], left: dict[int, str | None]) -> dict[str, Any]:
    """Each tracked frame measured as a photo with its points (`prism scan` of frame_points)."""
    from .video_scan import scan_video

    data = spec.model_dump(mode="json", exclude={"points", "points_frame", "frames", "fit"})
    data["frame_points"] = {str(i): to_reference(p).model_dump(mode="json") for i, p in good.items()}
    per_frame = ScanSpec.model_validate(data)
    summary = scan_video(per_frame, base, out, tiles=tiles, max_frames=max(max_frames, len(good)))
    summary["tracking"] = {"points_frame": spec.points_frame, "tracked": sorted(good),
                           "left_out": {str(i): r for i, r in sorted(left.items())}}
    (out / SUMMARY_NAME).write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def _joint(spec: ScanSpec, path: Path, out: Path, good: dict[int, np.ndarray],
           left: dict[int, str | None]) -> dict[str, Any]:
    """The tracked frames whose views differ most, measured as ONE box: joint.json."""
    assert isinstance(spec.scale, KnownEdge)  # the spec's rules
    # as many as JOINT_MAX_PIXELS lets be held decoded at once (the joint fit holds every view)
    info = probe_video(path)
    fit_at_once = max(2, JOINT_MAX_PIXELS // max(1, info.width * info.height))
    chosen = viewing_spread(good, min(JOINT_TRACKED_VIEWS, fit_at_once))
    views = [View(frame, good[index].tolist(), spec.side_face, f"frame {index}")
             for index, frame in iter_frames(path, chosen)]
    result = fit_views(views, spec.scale, focal_px=spec.focal_px)
    report = joint_report(result)
    report["tracking"] = {"points_frame": spec.points_frame, "tracked": sorted(good), "chosen": chosen,
                          "left_out": {str(i): r for i, r in sorted(left.items())}}
    (out / "joint.json").write_text(json.dumps(report, indent=2) + "\n")
    d = result.dimensions
    assert d.uncertainty is not None
    sizes = " x ".join(f"{v:.2f} (given)" if name == spec.scale.edge else f"{v:.2f} ± {s:.2f}"
                       for name, v, s in zip(("width", "height", "depth"), (d.width, d.height, d.depth),
                                             d.uncertainty, strict=True))
    console.print(f"[bold]{len(result.views)} of {len(views)} tracked frames as one box[/]  {sizes} mm  "
                  f"focal {result.focal_px:.0f} px", soft_wrap=True)
    for gone in result.left_out:
        console.print(f"[yellow]left out[/] {escape(gone.name)}: {escape(gone.reason)}", soft_wrap=True)
    for warning in (*result.warnings, *d.notes):
        console.print(f"[yellow]warning[/] {escape(warning)}", soft_wrap=True)
    console.print(f"joint: {out / 'joint.json'}")
    return report

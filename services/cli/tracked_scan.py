"""`prism scan VIDEO --points "..." --points-frame N`: points marked on one frame, tracked to the others.

The steps are the engine's (`prismcore.video.tracked`, which the worker shares): the seven
points marked on frame N are carried to every selected frame, each selected frame's points, or
the reason it is left out, go to ``tracked_points.json`` in the output folder, and the tracked
frames are measured one by one as `prism scan VIDEO` measures a video with `frame_points` (a
folder per frame, summary.json with a ``tracking`` block), or with fit "joint" as ONE box over
the frames whose views differ most: joint.json. This module reads and writes the files and
prints.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from rich.markup import escape

from prismcore.io import iter_frames, probe_video
from prismcore.multiview import joint_report
from prismcore.spec import JOINT_NAME, TRACKED_NAME, KnownEdge, ScanSpec
from prismcore.video import (
    Tracking,
    check_points_frame,
    fit_tracked,
    joint_frames,
    per_frame_spec,
    select_frames,
    track_video,
    tracked_json,
)

from .console import rich_console as console
from .joint_scan import write_part_files

__all__ = ["TRACKED_NAME", "scan_tracked"]


def scan_tracked(spec: ScanSpec, base: Path, out: Path, *, tiles: int, max_frames: int,
                 overlay_format: str = "jpeg") -> dict[str, Any]:
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
    check_points_frame(spec, info)
    indices = select_frames(path, spec.frames, info, max_frames=max_frames)
    console().print(f"{path}: {info.width}x{info.height}, {info.frame_count} frames; tracking the points of "
                  f"frame {spec.points_frame} to {len(indices)} selected frames")
    tick = time.process_time()
    tracked = track_video(spec, path, indices)
    cpu_s = time.process_time() - tick
    out.mkdir(parents=True, exist_ok=True)
    (out / TRACKED_NAME).write_text(json.dumps(tracked_json(tracked), indent=1) + "\n")
    tracking = Tracking.of(spec.points_frame, tracked)
    console().print(f"tracked {len(tracking.good)} of {len(tracked)} frames ({cpu_s:.1f} s CPU); points: "
                  f"{out / TRACKED_NAME}")
    for index, reason in tracking.left.items():
        console().print(f"[yellow]frame {index} left out:[/] {escape(str(reason))}", soft_wrap=True)
    tracking.require_some(repr(str(path)))
    if spec.fit == "joint":
        return _joint(spec, path, out, tracking)
    from .video_scan import scan_video

    return scan_video(per_frame_spec(spec, tracking), base, out, tiles=tiles,
                      max_frames=max_frames, extra={"tracking": tracking.block()},
                      overlay_format=overlay_format)


def _joint(spec: ScanSpec, path: Path, out: Path, tracking: Tracking) -> dict[str, Any]:
    """The tracked frames whose views differ most, measured as ONE box: joint.json."""
    assert isinstance(spec.scale, KnownEdge)  # the spec's rules
    chosen = joint_frames(tracking, probe_video(path))
    result = fit_tracked(spec, iter_frames(path, chosen), tracking)
    report = joint_report(result, chosen)
    report["tracking"] = tracking.block(chosen)
    (out / JOINT_NAME).write_text(json.dumps(report, indent=2) + "\n")
    parts = write_part_files(report, spec.scale, spec.part_formats, out, spec.nominal, spec.tolerance_mm)
    d = result.dimensions
    assert d.uncertainty is not None
    sizes = " x ".join(f"{v:.2f} (given)" if name == spec.scale.edge else f"{v:.2f} ± {s:.2f}"
                       for name, v, s in zip(("width", "height", "depth"), (d.width, d.height, d.depth),
                                             d.uncertainty, strict=True))
    console().print(f"[bold]{len(result.views)} of {len(chosen)} tracked frames as one box[/]  {sizes} mm  "
                  f"focal {result.focal_px:.0f} px", soft_wrap=True)
    for gone in result.left_out:
        console().print(f"[yellow]left out[/] {escape(gone.name)}: {escape(gone.reason)}", soft_wrap=True)
    for warning in (*result.warnings, *d.notes):
        console().print(f"[yellow]warning[/] {escape(warning)}", soft_wrap=True)
    console().print(f"joint: {out / JOINT_NAME}")
    for kind, where in parts.items():
        console().print(f"{kind}: {where}", soft_wrap=True)
    return report

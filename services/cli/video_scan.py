"""`prism scan VIDEO`: measure the selected frames of a video, one output folder per frame.

Each frame is measured as a photo (`frame_spec` + `run_scan`) and written to `frame_NNNNNN/`
like a photo's outputs (overlay.jpg included); `summary.json` beside them says how repeatable
each dimension is.
A frame that cannot be measured is reported and the others go on. With points "auto", a first
pass finds each frame's points in frame order (`prismcore.video.point_search.FrameSearch`); a frame
where the search refuses fails with its reason.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from rich.table import Table

from prismcore import InputError, ScanSpec
from prismcore.io import VideoInfo, iter_frames
from prismcore.locate import scan_found
from prismcore.report import FrameInfo, ScanReport
from prismcore.spec import SUMMARY_NAME, frame_folder
from prismcore.video import (
    DIMENSIONS,
    FrameSearch,
    PooledFocal,
    focal_estimate,
    frame_info,
    frame_spec,
    pool_focal,
    probe_video,
    select_frames,
    video_summary,
)

from .console import rich_console as console
from .outputs import write_scan

__all__ = ["scan_video"]


class _FrameSpecs:
    """Each frame's photo spec: the video spec's points, or with points "auto" those found in
    the frame (searched once, in frame order, before anything else reads the frames)."""

    def __init__(self, spec: ScanSpec, path: Path, indices: list[int]) -> None:
        self._spec = spec
        self._found: dict[int, tuple[ScanSpec, dict] | str] = {}
        if spec.auto_points is None:
            return
        search = FrameSearch(spec)
        try:
            for index, frame in iter_frames(path, indices):
                try:
                    resolved, found = search.resolve(index, frame)
                except InputError as exc:
                    self._found[index] = str(exc)
                else:
                    self._found[index] = (resolved, found.report())
        except InputError:
            pass  # the measuring pass meets the same break and reports it per frame

    def spec(self, index: int) -> tuple[ScanSpec, dict | None]:
        """Frame `index`'s photo spec and what the search found there (None: points given).

        Raises InputError with the search's reason for a frame where it found none.
        """
        if self._spec.auto_points is None:
            return frame_spec(self._spec, index), None
        found = self._found.get(index, f"points auto: frame {index} was not searched (decoding stopped)")
        if isinstance(found, str):
            raise InputError(found)
        return found


def _measure(specs: _FrameSpecs, index: int, frame: np.ndarray, info: VideoInfo, out: Path, tiles: int,
             decode_ms: float, pooled: PooledFocal | None, overlay_format: str) -> ScanReport:
    one, auto = specs.spec(index)
    result = scan_found(one, auto, frame, tiles=tiles, pooled_focal=pooled)
    result.report.frame = FrameInfo.model_validate(frame_info(index, info.fps))
    result.report.timings_ms["load"] = round(decode_ms, 3)
    folder = out / frame_folder(index)
    write_scan(result, one, folder, [frame], overlay_format, report=True)
    return result.report


def _pooled_focal(spec: ScanSpec, specs: _FrameSpecs, path: Path, indices: list[int]
                  ) -> tuple[PooledFocal, list[int]] | None:
    """All frames of one video share one focal length: when none is known, fit it on every
    frame first (the fit only, a fraction of a frame's cost) and pool the fits, so each frame is
    then measured with the steadier pooled value. Returns it with the frames it was pooled
    over; None when fewer than two frames give one."""
    if spec.focal_px is not None or spec.camera is not None:
        return None
    estimates, fitted = [], []
    try:
        for index, frame in iter_frames(path, indices):
            try:
                one = specs.spec(index)[0]
            except InputError:
                continue  # no points in this frame: it fails with the reason when measured
            found = focal_estimate(one, frame)
            if found is not None:
                estimates.append(found)
                fitted.append(index)
    except InputError:
        pass  # the measuring pass meets the same break and reports it per frame
    pooled = pool_focal(estimates) if len(estimates) >= 2 else None
    return None if pooled is None else (pooled, [fitted[i] for i in pooled.used])


def _table(summary: dict) -> Table:
    unit = summary["unit"]
    table = Table(title=f"{summary['frames']['measured']} frames measured, {unit}")
    for column in ("", "median", "min", "max", "spread", "std", "spread/median"):
        table.add_column(column, justify="right")
    for name in DIMENSIONS:
        s = summary["dimensions"][name]
        std = "-" if s["std"] is None else f"{s['std']:.3f}"
        rel = "-" if s["relative_spread"] is None else f"{s['relative_spread']:.2%}"
        table.add_row(name, *(f"{s[k]:.3f}" for k in ("median", "min", "max", "spread")), std, rel)
    return table


def scan_video(spec: ScanSpec, base: Path, out: Path, *, tiles: int, max_frames: int,
               extra: dict | None = None, overlay_format: str = "jpeg") -> dict:
    """Measure the frames `spec.frames` selects in the video `base / spec.image`; returns the summary.

    extra : more blocks for summary.json (the tracking of points marked on one frame).
    overlay_format : each frame's overlay picture as jpeg (overlay.jpg), png or webp.

    Raises
    ------
    InputError
        Not a video, nothing decodes, a bad or over-cap selection, or no frame measured.
    """
    path = base / spec.image
    if spec.frames is None:
        raise InputError(f"{str(path)!r} is a video: say which frames to measure "
                         '(e.g. "frames": {"every": 10} in the spec, or --every 10)')
    info = probe_video(path, max_pixels=spec.max_pixels)
    indices = select_frames(path, spec.frames, info, max_frames=max_frames)
    console().print(f"{path}: {info.width}x{info.height} {info.codec}, {info.frame_count} frames at "
                  f"{info.fps:g} fps; measuring {len(indices)}")
    specs = _FrameSpecs(spec, path, indices)
    found = _pooled_focal(spec, specs, path, indices)
    pooled = found[0] if found else None
    if found is not None:
        console().print(f"focal length pooled over {len(found[1])} frames: {found[0].focal_px:.1f} "
                      f"± {found[0].std_px:.1f} px")
    per_frame: dict[int, dict] = {}
    frames = iter_frames(path, indices)
    tick = time.perf_counter()
    try:
        for index, frame in frames:
            decode_ms = (time.perf_counter() - tick) * 1000
            try:
                report = _measure(specs, index, frame, info, out, tiles, decode_ms, pooled, overlay_format)
            except InputError as exc:
                per_frame[index] = {"error": str(exc)}
                console().print(f"[red]{frame_folder(index)} failed:[/] {exc}")
            else:
                d = report.dimensions
                per_frame[index] = {"dimensions": d.model_dump()}
                console().print(f"{frame_folder(index)}  {d.width:.2f} x {d.height:.2f} x "
                              f"{d.depth:.2f} {d.unit}  point loss {report.point_loss or 0.0:.1%}")
            tick = time.perf_counter()
    except InputError as exc:  # the stream broke: the frames not reached fail with its reason
        for index in indices:
            per_frame.setdefault(index, {"error": str(exc)})
        console().print(f"[red]decoding stopped:[/] {exc}")
    summary = video_summary(per_frame, fps=info.fps or None, video={"path": str(path), **asdict(info)},
                            selection=spec.frames, pooled=pooled, pooled_frames=found[1] if found else (),
                            extra=extra)
    out.mkdir(parents=True, exist_ok=True)
    (out / SUMMARY_NAME).write_text(json.dumps(summary, indent=2) + "\n")
    if not summary["frames"]["measured"]:
        first = summary["failed"][0]
        raise InputError(f"no frame of {str(path)!r} could be measured; frame {first['frame']}: "
                         f"{first['error']}")
    console().print(_table(summary))
    console().print(f"summary: {out / SUMMARY_NAME}")
    return summary

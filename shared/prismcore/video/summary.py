"""A video job's summary: how repeatable each dimension is across the frames measured.

Pure: report dicts in, a JSON-ready dict out (stdlib only, so any service part can build it).
`video_summary` is summary.json, the same document from the CLI and the worker.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from prismcore.scan.focal import PooledFocal
    from prismcore.spec import FrameSelection

__all__ = ["DECIMALS", "DIMENSIONS", "frame_info", "summarize", "video_summary"]

DIMENSIONS = ("width", "height", "depth")
DECIMALS = 6  # the figures are rounded to this many decimals (the reports' dimensions have 4)


def _stats(values: list[float]) -> dict[str, float | None]:
    median = statistics.median(values)
    spread = max(values) - min(values)
    stats = {
        "median": median,
        "min": min(values),
        "max": max(values),
        "spread": spread,
        # the sample standard deviation: the frames are a sample of repeated measurements
        "std": statistics.stdev(values) if len(values) > 1 else None,
        "relative_spread": spread / abs(median) if median else None,
    }
    return {k: None if v is None else round(v, DECIMALS) for k, v in stats.items()}


def frame_info(index: int, fps: float | None) -> dict[str, int | float | None]:
    """What a frame's report.json says of the frame: ``{"index", "time_s"}`` (s; None without
    a frame rate)."""
    return {"index": int(index), "time_s": round(index / fps, 6) if fps else None}


def summarize(per_frame: Mapping[int, Mapping[str, Any]], *, fps: float | None = None) -> dict[str, Any]:
    """Median and spread of each dimension over the frames of one video.

    Parameters
    ----------
    per_frame : mapping of int to dict
        Frame index -> that frame's report (the `report.json` content; only its "dimensions"
        are read), or ``{"error": message}`` for a frame that could not be measured.
    fps : float, optional
        The video's frame rate; when given, each frame's time (index / fps, s) is listed.

    Returns
    -------
    dict
        ``frames``: counts ``selected``, ``measured``, ``failed``.
        ``unit``: the dimensions' unit ("mm", or "px" without a scale; None if none measured).
        ``dimensions``: per dimension (width, height, depth) ``median``, ``min``, ``max``,
        ``spread`` (max - min), ``std`` (sample standard deviation; None for one frame) and
        ``relative_spread`` (spread / median); empty when no frame was measured.
        ``per_frame``: ``{"frame", ["time_s"], "width", "height", "depth"}`` per measured frame.
        ``failed``: ``{"frame", "error"}`` per failed frame. Lists are in frame order.

    Raises
    ------
    ValueError
        A report without dimensions, or frames measured in different units.
    """
    measured, failed = [], []
    for index in sorted(per_frame):
        report = per_frame[index]
        if "error" in report:
            failed.append({"frame": int(index), "error": str(report["error"])})
            continue
        dims = report.get("dimensions")
        if not isinstance(dims, Mapping):
            raise ValueError(f"frame {index}: the report has no dimensions and no error")
        row: dict[str, Any] = {"frame": int(index)}
        if fps:
            row["time_s"] = frame_info(index, fps)["time_s"]
        row.update({k: float(dims[k]) for k in DIMENSIONS})
        row["unit"] = dims.get("unit")
        measured.append(row)
    units = {row.pop("unit") for row in measured}
    if len(units) > 1:
        raise ValueError(f"frames measured in different units: {sorted(map(str, units))}")
    dimensions = {k: _stats([row[k] for row in measured]) for k in DIMENSIONS} if measured else {}
    return {
        "frames": {"selected": len(per_frame), "measured": len(measured), "failed": len(failed)},
        "unit": units.pop() if units else None,
        "dimensions": dimensions,
        "per_frame": measured,
        "failed": failed,
    }


def video_summary(per_frame: Mapping[int, Mapping[str, Any]], *, fps: float | None,
                  video: Mapping[str, Any], selection: FrameSelection, pooled: PooledFocal | None = None,
                  pooled_frames: Sequence[int] = (), extra: Mapping[str, Any] | None = None
                  ) -> dict[str, Any]:
    """A video's summary.json: `summarize`'s figures, then the video, the frames selected, the
    focal length pooled over the frames (when one was) and `extra` blocks, in that order.

    Parameters
    ----------
    per_frame, fps
        As `summarize`.
    video : mapping
        What names and describes the video: the CLI's path, the service's reference, with the
        probe's frame count, fps, size, codec and duration.
    selection : FrameSelection
        The spec's `frames`.
    pooled : PooledFocal, optional
        The focal length pooled over the frames' own fits; `pooled_frames` the frames it was
        pooled over.
    extra : mapping, optional
        More blocks (the tracking of points marked on one frame: ``{"tracking": ...}``).
    """
    summary = summarize(per_frame, fps=fps)
    summary["video"] = dict(video)
    summary["selection"] = selection.model_dump(mode="json", exclude_none=True)
    if pooled is not None:
        summary["focal"] = {"pooled_px": round(pooled.focal_px, 3), "std_px": round(pooled.std_px, 3),
                            "frames": list(pooled_frames)}
    summary.update(extra or {})
    return summary

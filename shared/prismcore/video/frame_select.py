"""Which frames of a video to measure: a `FrameSelection` turned into frame indices, under a cap."""

from __future__ import annotations

import math

import cv2
import numpy as np

from prismcore.errors import InputError
from prismcore.io.video_decode import PathLike, VideoInfo, decode_bgr
from prismcore.spec import FrameSelection

__all__ = ["DEFAULT_MAX_FRAMES", "frame_sharpness", "select_frames", "viewing_spread"]

DEFAULT_MAX_FRAMES = 500
"""The CLI's cap on frames measured per video (the service has its own setting)."""

SHARPNESS_WIDTH = 640
"""Frames wider than this are shrunk to it before rating: blur that matters at full size still
shows, and the pass over many candidate frames costs less."""

_NARROW = "narrow it with every, start_s/end_s, indices or sharpest"


def frame_sharpness(frame: np.ndarray) -> float:
    """Variance of the Laplacian of a frame's grey levels: higher is sharper.

    Parameters
    ----------
    frame : ndarray
        (H, W, 3) uint8, RGB or BGR (the grey weights differ slightly; rankings within one
        video do not depend on which), or (H, W) grey.

    Returns
    -------
    float
        In grey levels squared, measured at most `SHARPNESS_WIDTH` px wide.
    """
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    if gray.shape[1] > SHARPNESS_WIDTH:
        height = max(1, round(gray.shape[0] * SHARPNESS_WIDTH / gray.shape[1]))
        gray = cv2.resize(gray, (SHARPNESS_WIDTH, height), interpolation=cv2.INTER_AREA)
    _, std = cv2.meanStdDev(cv2.Laplacian(gray, cv2.CV_32F))
    return float(std[0, 0]) ** 2


def _candidates(selection: FrameSelection, info: VideoInfo, label: str) -> range:
    """The frames in [start_s, end_s), every Nth from the first."""
    n = info.frame_count
    first, stop = 0, n
    if selection.start_s is not None or selection.end_s is not None:
        if info.fps <= 0:
            raise InputError(f"{label} states no frame rate, so a time range cannot be used: "
                             "give frame indices instead")
        # frame i is shown at i / fps; the small slack keeps 0.4 s * 25 fps at frame 10, not 11
        if selection.start_s is not None:
            first = math.ceil(selection.start_s * info.fps - 1e-6)
        if selection.end_s is not None:
            stop = min(n, math.ceil(selection.end_s * info.fps - 1e-6))
        if first >= n:
            raise InputError(f"start_s {selection.start_s!r} is past the end of {label} "
                             f"({info.duration_s:.3f} s, {n} frames)")
    chosen = range(first, stop, selection.every or 1)
    if len(chosen) == 0:
        raise InputError(f"the selection {selection.model_dump_json(exclude_none=True)} picks no "
                         f"frame of {label} ({info.duration_s:.3f} s, {n} frames at {info.fps:g} fps)")
    return chosen


def _sharpest(path: PathLike, candidates: range, k: int) -> list[int]:
    scores = {index: frame_sharpness(bgr) for index, bgr in decode_bgr(path, candidates)}
    best = sorted(scores, key=lambda i: (-scores[i], i))[:k]  # ties: the earlier frame
    return sorted(best)


def select_frames(path: PathLike, selection: FrameSelection, info: VideoInfo, *,
                  max_frames: int) -> list[int]:
    """The frames a selection picks, sorted, checked against the video and the cap.

    Parameters
    ----------
    path : str or os.PathLike
        The video; decoded only for `sharpest` (a streaming pass over the candidates, grey,
        at most `SHARPNESS_WIDTH` px wide).
    selection : FrameSelection
        The spec's `frames`.
    info : VideoInfo
        From `probe_video(path)`.
    max_frames : int
        Most frames one video may have measured.

    Returns
    -------
    list of int
        Frame indices, increasing, each below `info.frame_count`.

    Raises
    ------
    InputError
        Indices out of range, a selection that picks no frame, more `sharpest` than candidates,
        a time range without a frame rate, or more than `max_frames` frames.
    """
    if max_frames < 1:
        raise ValueError(f"max_frames must be at least 1, got {max_frames!r}")
    label = repr(str(path))
    n = info.frame_count
    if selection.indices is not None:
        bad = [i for i in selection.indices if i >= n]
        if bad:
            shown = ", ".join(map(str, bad[:5])) + (", ..." if len(bad) > 5 else "")
            raise InputError(f"frame indices {shown} out of range: {label} has {n} frames (0-{n - 1})")
        chosen: range | list[int] = sorted(selection.indices)
    else:
        chosen = _candidates(selection, info, label)
        if selection.sharpest is not None:
            if selection.sharpest > len(chosen):
                raise InputError(f"sharpest {selection.sharpest} is more than the {len(chosen)} "
                                 f"candidate frames of {label}")
            if selection.sharpest > max_frames:
                raise InputError(f"sharpest {selection.sharpest} is over the cap of {max_frames} "
                                 "frames per video")
            chosen = _sharpest(path, chosen, selection.sharpest)
    if len(chosen) > max_frames:
        raise InputError(f"the selection picks {len(chosen)} frames of {label}, over the cap of "
                         f"{max_frames} frames per video: {_NARROW}")
    return list(chosen)


def viewing_spread(points: dict[int, np.ndarray], count: int) -> list[int]:
    """The frames whose views of the box differ most: farthest-point sampling of the seven
    points' shape (centred, scaled to unit size), which changes as the viewing angle does.

    Parameters
    ----------
    points : dict of int to ndarray, shape (7, 2)
        Each frame's points.
    count : int
        How many frames to choose (all when fewer).

    Returns
    -------
    list of int
        The chosen frame indices, increasing.
    """
    keys = sorted(points)
    if len(keys) <= count:
        return keys
    shapes = []
    for key in keys:
        p = points[key] - points[key].mean(axis=0)
        shapes.append((p / max(float(np.sqrt((p**2).sum(axis=1).mean())), 1e-9)).ravel())
    x = np.array(shapes)
    centre = x.mean(axis=0)
    chosen = [int(np.argmax(np.linalg.norm(x - centre, axis=1)))]
    dist = np.linalg.norm(x - x[chosen[0]], axis=1)
    while len(chosen) < count:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(x - x[nxt], axis=1))
    return sorted(keys[i] for i in chosen)

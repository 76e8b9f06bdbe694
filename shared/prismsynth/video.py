"""Short videos of a box of known size, for tests and benchmarks: a camera swaying slightly.

Frames are `render.render_oblique_view` renders of one scene (same seed, so the same box,
texture and background) from poses that sway around a mean view at a fixed distance, and are
encoded with OpenCV's VideoWriter, or for H.264 with the ffmpeg of `imageio-ffmpeg` (a test
dependency: OpenCV's wheels do not encode H.264).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable

import cv2
import numpy as np

from .render import DEFAULT_STYLE, Box, Scene, Style, render_oblique_view

__all__ = ["render_clip", "write_video"]


def render_clip(box: Box, frames: int, *, image_size: tuple[int, int] = (640, 512),
                focal_px: float = 1400.0, distance_mm: float | None = None, yaw_deg: float = 30.0,
                pitch_deg: float = 15.0, sway_deg: float = 0.5, style: Style = DEFAULT_STYLE,
                seed: int = 0) -> list[Scene]:
    """Frames of a hand-held camera looking at a box: yaw and pitch sway by up to `sway_deg`.

    Frame i is seen from yaw ``yaw_deg + sway_deg * sin(2 pi i / frames)`` and pitch
    ``pitch_deg + sway_deg * cos(2 pi i / frames) / 2``, always `distance_mm` from the front face's
    centre (None: the first pose's automatic distance, then kept). Other parameters as in
    `render_oblique_view`; each scene carries its exact reference points.
    """
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames!r}")
    scenes: list[Scene] = []
    for i in range(frames):
        phase = 2.0 * math.pi * i / frames
        scenes.append(render_oblique_view(
            box, image_size=image_size, focal_px=focal_px, distance_mm=distance_mm,
            yaw_deg=yaw_deg + sway_deg * math.sin(phase),
            pitch_deg=pitch_deg + 0.5 * sway_deg * math.cos(phase), style=style, seed=seed))
        distance_mm = scenes[0].distance_mm
    return scenes


def write_video(frames: Iterable[np.ndarray], path: str | os.PathLike[str], *, codec: str = "MJPG",
                fps: float = 25.0) -> None:
    """Encode RGB uint8 frames (H, W, 3), all the same size, into a video file, streaming.

    Parameters
    ----------
    frames : iterable of ndarray
        RGB uint8 (H, W, 3).
    path : str or os.PathLike
        The file; its extension picks the container (.avi, .mp4, .mov, .mkv).
    codec : str
        An OpenCV FourCC ("MJPG", "XVID", "mp4v", ...), or "h264" for libx264 through
        imageio-ffmpeg (yuv420p, so width and height should be even).
    fps : float
        Frames per second written in the file.

    Raises
    ------
    RuntimeError
        The encoder cannot be opened for this codec and container.
    """
    frames = iter(frames)
    first = next(frames, None)
    if first is None:
        raise ValueError("no frames to write")
    height, width = first.shape[:2]
    if codec.lower() == "h264":
        import imageio_ffmpeg  # a test dependency, loaded only for H.264

        writer = imageio_ffmpeg.write_frames(os.fspath(path), (width, height), fps=fps, codec="libx264",
                                             macro_block_size=1, ffmpeg_log_level="error",
                                             output_params=["-crf", "18"])
        writer.send(None)
        try:
            for frame in _chain(first, frames):
                writer.send(np.ascontiguousarray(frame))
        finally:
            writer.close()
        return
    out = cv2.VideoWriter(os.fspath(path), cv2.VideoWriter.fourcc(*codec), fps, (width, height))
    if not out.isOpened():
        raise RuntimeError(f"OpenCV cannot encode {codec!r} into {os.fspath(path)!r}")
    try:
        for frame in _chain(first, frames):
            if frame.shape[:2] != (height, width):
                raise ValueError(f"frame of shape {frame.shape} in a {width}x{height} video")
            out.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    finally:
        out.release()


def _chain(first: np.ndarray, rest: Iterable[np.ndarray]) -> Iterable[np.ndarray]:
    yield first
    yield from rest

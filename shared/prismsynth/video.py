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

from .models import DEFAULT_STYLE, Box, Scene, Style
from .render import render_oblique_view

__all__ = ["moving_clip", "render_clip", "write_video"]


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


def moving_clip(box: Box, frames: int, *, image_size: tuple[int, int] = (960, 540), focal_px: float = 900.0,
                yaw_deg: float = 30.0, pitch_deg: float = 15.0, sway_deg: float = 8.0,
                noise_sigma: float = 2.0, blur_sigma: float = 0.8, jpeg_quality: int = 85,
                seed: int = 0) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """A hand-held camera's clip of one box whose texture stays put (`Style.texel_mm` fixed), with
    fresh sensor noise every frame, optical blur and a JPEG round trip per frame.

    Returns
    -------
    frames : list of ndarray, shape (H, W, 3), uint8 RGB
    points : list of ndarray, shape (7, 2), float64
        Each frame's exact P1..P7 (image px).
    """
    base = render_clip(box, 1, image_size=image_size, focal_px=focal_px, yaw_deg=yaw_deg,
                       pitch_deg=pitch_deg, sway_deg=0.0, seed=seed)[0]
    texel_mm = base.distance_mm / focal_px / 1.5
    style = Style(noise_sigma=0.0, blur_sigma=blur_sigma, jpeg_quality=None, texel_mm=texel_mm)
    scenes = render_clip(box, frames, image_size=image_size, focal_px=focal_px, yaw_deg=yaw_deg,
                         pitch_deg=pitch_deg, sway_deg=sway_deg, style=style, seed=seed)
    rng = np.random.default_rng(seed + 1)
    images, points = [], []
    for scene in scenes:
        noisy = scene.image.astype(np.float32) + rng.normal(0.0, noise_sigma, scene.image.shape)
        img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR),
                               [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if decoded is None:
            raise RuntimeError("JPEG decoding failed")
        images.append(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB))
        points.append(np.array([scene.points[n] for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")]))
    return images, points

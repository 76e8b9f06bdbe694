"""Decoding videos: probe a file, stream chosen frames (the OpenCV boundary for videos).

OpenCV's VideoCapture (the FFmpeg it bundles) reads from a file path, so these functions take
paths. Frames come out one at a time as RGB uint8 arrays (H, W, 3); the video is never held in
memory. Frame indices count decoded frames from 0; frame i is shown at i / fps seconds.
"""

from __future__ import annotations

import math
import os
from collections.abc import Generator, Iterable, Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass

import cv2
import numpy as np

from prismcore.errors import InputError
from prismcore.io.containers import HEAD_BYTES, video_container

__all__ = ["SEEK_GAP", "VideoInfo", "decode_bgr", "is_video", "iter_frames", "probe_video"]

# FFmpeg logs a broken file's faults on stderr; the InputError raised here says what is wrong in
# one line, so FFmpeg's own log stays off unless the user sets the variable to see it.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

SEEK_GAP = 48
"""Frames: a longer jump forward is made by seeking, a shorter one by decoding through it
(a seek decodes from the previous key frame anyway)."""

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class VideoInfo:
    """What :func:`probe_video` found.

    Attributes
    ----------
    frame_count : int
        Frames that decode, counted when the header's claim does not hold.
    fps : float
        Frames per second the file states; 0.0 when it states none (time ranges then fail).
    width, height : int
        Frame size, px.
    codec : str
        FourCC as OpenCV reports it, e.g. "MJPG", "FMP4" (MPEG-4 part 2), "avc1" or "H264".
    duration_s : float
        frame_count / fps, seconds (0.0 without a frame rate).
    """

    frame_count: int
    fps: float
    width: int
    height: int
    codec: str
    duration_s: float


def is_video(data_or_path: PathLike | bytes | bytearray | memoryview) -> bool:
    """True when the content (bytes, or the file at a path) starts like AVI, MP4, MOV or MKV.

    The name is not trusted, only the first bytes. A path that cannot be read is not a video.
    """
    if isinstance(data_or_path, bytes | bytearray | memoryview):
        return video_container(data_or_path) is not None
    try:
        with open(data_or_path, "rb") as f:
            return video_container(f.read(HEAD_BYTES)) is not None
    except OSError:
        return False


@contextmanager
def _quiet() -> Iterator[None]:
    # OpenCV warns on stderr when a backend refuses a file; the caller raises its own error.
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)


def _open(path: PathLike) -> tuple[cv2.VideoCapture, str]:
    """An opened capture and the file's container; InputError when it is not a video."""
    label = repr(str(path))
    try:
        with open(path, "rb") as f:
            head = f.read(HEAD_BYTES)
    except OSError as exc:
        raise InputError(f"cannot read {label}: {exc.strerror or exc}") from None
    container = video_container(head)
    if container is None:
        raise InputError(f"{label} is not a video (AVI, MP4, MOV or MKV): it starts with {head[:8]!r}")
    with _quiet():
        cap = cv2.VideoCapture(os.fspath(path), cv2.CAP_FFMPEG)
    if not cap.isOpened():
        raise InputError(f"{label} is a truncated or corrupt {container.upper()} video: it does not open")
    return cap, container


def _fourcc(cap: cv2.VideoCapture) -> str:
    code = int(cap.get(cv2.CAP_PROP_FOURCC)) & 0xFFFFFFFF
    text = code.to_bytes(4, "little").decode("latin-1").strip("\x00 ")
    return text if text.isprintable() and text else "unknown"


def _count_frames(path: PathLike, cap: cv2.VideoCapture, claimed: int) -> int:
    """Frames that decode. The header's count is checked at its end, and counted when wrong."""
    if claimed > 0:
        cap.set(cv2.CAP_PROP_POS_FRAMES, claimed - 1)
        if int(cap.get(cv2.CAP_PROP_POS_FRAMES)) == claimed - 1 and cap.grab() and not cap.grab():
            return claimed
    # Truncated files claim frames they lack; some streams claim none: decode them all to know.
    recount, _ = _open(path)
    try:
        count = 0
        while recount.grab():
            count += 1
        return count
    finally:
        recount.release()


def probe_video(path: PathLike, *, max_pixels: int | None = None) -> VideoInfo:
    """Check that a file is a video with decodable frames, and read its size, rate and codec.

    Parameters
    ----------
    path : str or os.PathLike
        The video file (the content decides, not the name).
    max_pixels : int, optional
        Largest frame (width * height) accepted.

    Raises
    ------
    InputError
        Missing or unreadable file, not a video, a video that does not open or has no
        decodable frame, frames over `max_pixels`.
    """
    label = repr(str(path))
    cap, container = _open(path)
    try:
        width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if max_pixels is not None and width * height > max_pixels:
            raise InputError(f"{label} has {width}x{height} = {width * height} pixel frames, over the "
                             f"limit of {max_pixels} pixels")
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        fps = fps if math.isfinite(fps) and fps > 0 else 0.0
        codec = _fourcc(cap)
        ok, first = cap.read()
        if not ok or first is None or first.shape[:2] != (height, width):
            raise InputError(f"{label} has no decodable frames ({container.upper()}, codec {codec})")
        count = _count_frames(path, cap, int(cap.get(cv2.CAP_PROP_FRAME_COUNT)))
    finally:
        cap.release()
    if count == 0:  # the first frame read, then a recount found none: the file changed under us
        raise InputError(f"{label} has no decodable frames ({container.upper()}, codec {codec})")
    return VideoInfo(count, fps, width, height, codec, count / fps if fps else 0.0)


def iter_frames(path: PathLike, indices: Iterable[int], *,
                seek_gap: int = SEEK_GAP) -> Iterator[tuple[int, np.ndarray]]:
    """Decode the given frames one by one, in index order.

    Frames between two wanted ones are decoded and dropped (no colour conversion) unless the
    gap exceeds `seek_gap`, where a seek is cheaper. Only the frame being yielded is held.

    Parameters
    ----------
    path : str or os.PathLike
        The video file.
    indices : iterable of int
        Frames wanted (0-based); repeats are yielded once, in increasing order.
    seek_gap : int, default SEEK_GAP
        Longest forward gap decoded through rather than sought across.

    Yields
    ------
    (int, ndarray)
        The frame index, and the frame as RGB uint8 (H, W, 3), C-contiguous, owned by the caller.

    Raises
    ------
    InputError
        Not a video, a negative index, or an index past the last frame that decodes.
    """
    frames = decode_bgr(path, indices, seek_gap=seek_gap)
    with closing(frames):  # the capture is released as soon as the caller stops, not at GC
        for index, bgr in frames:
            yield index, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def decode_bgr(path: PathLike, indices: Iterable[int], *,
               seek_gap: int = SEEK_GAP) -> Generator[tuple[int, np.ndarray], None, None]:
    """As :func:`iter_frames`, but each frame is OpenCV's BGR array, reused for the next frame.

    For passes that reduce each frame at once (the sharpness rating); keep nothing it yields.
    """
    wanted = sorted({int(i) for i in indices})
    if wanted and wanted[0] < 0:
        raise InputError(f"frame index {wanted[0]} is negative")
    if not wanted:
        return
    label = repr(str(path))
    cap, _ = _open(path)
    try:
        pos = 0  # the index of the frame the next grab() decodes
        bgr = None
        for index in wanted:
            if index - pos > seek_gap:
                cap.set(cv2.CAP_PROP_POS_FRAMES, index)
                if int(cap.get(cv2.CAP_PROP_POS_FRAMES)) == index:
                    pos = index
                else:  # the demuxer could not land exactly: walk from the start instead
                    cap.release()
                    cap, _ = _open(path)
                    pos = 0
            while pos < index and cap.grab():
                pos += 1
            ok, bgr = cap.read(bgr)
            if pos < index or not ok:
                raise InputError(f"frame {index} is past the end of {label}: "
                                 f"only frames 0-{pos - 1} decode")
            pos += 1
            yield index, bgr
    finally:
        cap.release()

"""What an upload is, found when it is stored: photo or video, format, pixel size, frames.

A photo is probed from its first bytes (`prismcore.images.probe_image` reads the header only);
a video from a copy of it on local disk (`prismcore.video_decode.probe_video`: OpenCV reads
files only). Both are the engine's own readers, so what the upload is said to be is what a
worker will find. The engine (numpy, OpenCV) is imported on the first upload, not when the API
starts. A file that is neither a photo the engine reads nor a video is :class:`Unsupported`,
named by what it looks like.
"""

from __future__ import annotations

import os
from typing import Any

from prismcore.containers import HEAD_BYTES, video_container

__all__ = ["Unsupported", "detect_type", "is_video_head", "probe_image_head", "probe_video_file"]

# Recognised only to name a refused file: (leading bytes, what it is).
_KNOWN: tuple[tuple[bytes, str], ...] = (
    (b"%PDF", "a PDF document (application/pdf)"),
    (b"GIF87a", "a GIF image (image/gif)"),
    (b"GIF89a", "a GIF image (image/gif)"),
    (b"PK\x03\x04", "a ZIP archive (application/zip)"),
    (b"\x1f\x8b", "gzip data (application/gzip)"),
    (b"\x00\x00\x00\x0cJXL ", "a JPEG XL image (image/jxl)"),
    (b"\xff\x0a", "a JPEG XL image (image/jxl)"),
    (b"\x00\x00\x00\x0cjP  ", "a JPEG 2000 image (image/jp2)"),
    (b"OggS", "Ogg media (application/ogg)"),
    (b"ID3", "MP3 audio (audio/mpeg)"),
)


class Unsupported(Exception):  # noqa: N818 - a finding, not a failure of the code
    """Neither a photo the engine reads nor a video: `detected` says what it seems to be."""

    def __init__(self, detected: str) -> None:
        super().__init__(detected)
        self.detected = detected


def detect_type(head: bytes) -> str:
    """What a file that is no photo or video seems to be, in words with its media type."""
    for magic, what in _KNOWN:
        if head.startswith(magic):
            return what
    if head[4:8] == b"ftyp":
        brand = head[8:12].decode("latin-1").strip()
        return f"a HEIF/AVIF image ({brand}; image/heif)"
    if head[:4] == b"RIFF":
        return f"a RIFF {head[8:12].decode('latin-1').strip()!r} file, not AVI or WebP"
    sample = head[:4096]
    try:
        text: str | None = sample.decode("utf-8")
    except UnicodeDecodeError as exc:
        # A multi-byte character cut at the sample's end is still text.
        text = sample[: exc.start].decode("utf-8") if exc.start >= len(sample) - 3 else None
    if text is not None and all(c.isprintable() or c in "\t\r\n\f" for c in text):
        lowered = text.lstrip("\ufeff \t\r\n").lower()
        if lowered.startswith("<svg") or ("<svg" in lowered[:1000] and lowered.startswith("<?xml")):
            return "an SVG drawing (image/svg+xml)"
        if lowered.startswith(("<!doctype html", "<html")):
            return "an HTML page (text/html)"
        if lowered.startswith(("{", "[")):
            return "JSON or other text (application/json)"
        return "text (text/plain)"
    return f"unrecognised binary data (application/octet-stream) starting with {head[:8]!r}"


def is_video_head(head: bytes) -> bool:
    """True when the first bytes announce a video container (AVI, MP4, MOV, MKV)."""
    return video_container(head[:HEAD_BYTES]) is not None


def probe_image_head(head: bytes, *, complete: bool, name: str) -> dict[str, Any]:
    """The probe of a photo from its first bytes (`complete`: they are the whole file).

    Returns ``{"kind": "image", "format", "width", "height"}`` with the size the engine sees
    (after EXIF orientation), or without the size (and with ``"error"``) when the header cannot
    be read from these bytes: damage is for the worker to report, with its own message.

    Raises
    ------
    Unsupported
        Not one of the engine's photo formats, and not a video.
    """
    from prismcore.errors import InputError
    from prismcore.images import _sniff, probe_image

    label = repr(name)
    try:
        fmt = _sniff(head, label)
    except InputError:
        raise Unsupported(detect_type(head)) from None
    try:
        info = probe_image(head, name=name)
    except InputError as exc:
        if not complete:  # the header runs past the bytes kept (a huge EXIF block, a TIFF's IFD)
            return {"kind": "image", "format": fmt}
        return {"kind": "image", "format": fmt, "error": str(exc)}
    height, width = info.shape[:2]
    return {"kind": "image", "format": info.format, "width": width, "height": height}


def probe_video_file(path: str | os.PathLike, *, head: bytes, name: str) -> dict[str, Any]:
    """The probe of a video stored at `path` (a local copy of the upload named `name`).

    Returns ``{"kind": "video", "format", "width", "height", "frame_count", "fps", "codec"}``,
    or ``{"kind": "video", "format", "error"}`` for a video that does not decode (a cut clip may
    still hold frames a worker measures, so it is recorded, not refused).
    """
    from prismcore.errors import InputError
    from prismcore.video_decode import probe_video

    container = (video_container(head[:HEAD_BYTES]) or "video").upper()
    try:
        info = probe_video(path)
    except InputError as exc:
        # The engine names the file by its path: the client knows it by its name.
        return {"kind": "video", "format": container,
                "error": str(exc).replace(repr(str(path)), repr(name))}
    return {"kind": "video", "format": container, "width": info.width, "height": info.height,
            "frame_count": info.frame_count, "fps": round(info.fps, 6), "codec": info.codec}

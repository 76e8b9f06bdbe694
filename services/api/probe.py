"""What an upload is, found when it is stored: photo or video, format, pixel size, frames.

A photo is probed from its first bytes (`prismcore.io.images.probe_image` reads the header only);
a video from a copy of it on local disk (`prismcore.io.video_decode.probe_video`: OpenCV reads
files only). Both are the engine's own readers, so what the upload is said to be is what a
worker will find. The engine (numpy, OpenCV) is imported on the first upload, not when the API
starts. A file that is neither a photo the engine reads nor a video is :class:`Unsupported`,
named by what it looks like. A JPEG, PNG or WebP photo cut short (its header whole, the rest
missing: a copy interrupted) is found as it streams past (:class:`ImageEnd`) and refused too.
"""

from __future__ import annotations

import os
from typing import Any

from prismcore.io.containers import HEAD_BYTES, video_container

__all__ = ["ImageEnd", "Unsupported", "detect_type", "is_video_head", "probe_image_head",
           "probe_video_file"]

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


class ImageEnd:
    """Fed a photo's bytes as they pass, says whether the photo's end was in them.

    A JPEG ends at the end-of-image marker that follows its scans (the segments are walked by
    their lengths, the entropy-coded data scanned for its next marker: an EXIF thumbnail's own
    marker, or data appended after the image, as motion photos have, are not mistaken for it);
    a PNG at its IEND chunk (the chunks walked by their lengths); a WebP where its RIFF header's
    size says. Other formats (BMP, TIFF) are not checked here: the worker reports them damaged.
    """

    def __init__(self, head: bytes) -> None:
        self.format = ("JPEG" if head.startswith(b"\xff\xd8\xff") else
                       "PNG" if head.startswith(b"\x89PNG\r\n\x1a\n") else
                       "WEBP" if head[:4] == b"RIFF" and head[8:12] == b"WEBP" else None)
        self.size = 0
        self.ended = self.format is None  # nothing to check
        self._buf = b""
        self._skip = 2 if self.format == "JPEG" else 8 if self.format == "PNG" else 0  # SOI, signature
        self._entropy = False
        self._riff = int.from_bytes(head[4:8], "little") + 8 if self.format == "WEBP" else 0

    def feed(self, data: bytes) -> None:
        self.size += len(data)
        if self.ended:
            return
        if self.format == "WEBP":
            self.ended = self.size >= self._riff
            return
        if self._skip:
            n = min(self._skip, len(data))
            self._skip -= n
            data = data[n:]
        buf = self._buf + data
        i = self._jpeg(buf) if self.format == "JPEG" else self._png(buf)
        self._buf = buf[i:]

    def _jpeg(self, buf: bytes) -> int:
        """Walk `buf` from its start; the offset of the first byte not yet understood."""
        i = 0
        while True:
            if self._entropy:  # scan data: ff 00 (a stuffed ff) and ff d0-d7 (restarts) belong to it
                j = buf.find(b"\xff", i)
                if j < 0 or j + 1 >= len(buf):
                    return len(buf) if j < 0 else j
                marker = buf[j + 1]
                if marker == 0 or 0xD0 <= marker <= 0xD7:
                    i = j + 2
                    continue
                self._entropy, i = False, j
                continue
            if len(buf) - i < 2:
                return i
            if buf[i] != 0xFF:  # stray bytes before a marker: decoders skip them, so do we
                j = buf.find(b"\xff", i)
                i = len(buf) if j < 0 else j
                continue
            marker = buf[i + 1]
            if marker == 0xFF:  # fill byte
                i += 1
            elif marker == 0xD9:
                self.ended = True
                return len(buf)
            elif marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:  # no length
                i += 2
            else:
                if len(buf) - i < 4:
                    return i
                end = i + 2 + int.from_bytes(buf[i + 2 : i + 4], "big")
                self._entropy = marker == 0xDA  # start of scan: its data follows the header
                if end > len(buf):
                    self._skip = end - len(buf)
                    return len(buf)
                i = end

    def _png(self, buf: bytes) -> int:
        i = 0
        while len(buf) - i >= 8:
            length, kind = int.from_bytes(buf[i : i + 4], "big"), buf[i + 4 : i + 8]
            if kind == b"IEND":
                self.ended = True
                return len(buf)
            end = i + 12 + length
            if end > len(buf):
                self._skip = end - len(buf)
                return len(buf)
            i = end
        return i

    def problem(self, name: str) -> str | None:
        """Why the photo is cut short, once every byte was fed; None when it is whole."""
        if self.ended:
            return None
        end = {"JPEG": "its end-of-image marker", "PNG": "its IEND chunk",
               "WEBP": f"the {self._riff:,} bytes its header announces"}[self.format or ""]
        return (f"{name!r} is a truncated {self.format} ({self.size:,} bytes, cut short before {end}): "
                "the file was not copied whole; upload the complete photo")


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
    from prismcore.io.images import _sniff, probe_image

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
    from prismcore.io.video_decode import probe_video

    container = (video_container(head[:HEAD_BYTES]) or "video").upper()
    try:
        info = probe_video(path)
    except InputError as exc:
        # The engine names the file by its path: the client knows it by its name.
        return {"kind": "video", "format": container,
                "error": str(exc).replace(repr(str(path)), repr(name))}
    return {"kind": "video", "format": container, "width": info.width, "height": info.height,
            "frame_count": info.frame_count, "fps": round(info.fps, 6), "codec": info.codec}

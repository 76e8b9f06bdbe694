"""What an upload is, found when it is stored: photo or video, format, pixel size, frames.

A photo is probed from its first bytes (`prismcore.io.images.probe_image` reads the header only);
a video from a copy of it on local disk (`prismcore.io.video_decode.probe_video`: OpenCV reads
files only). Both are the engine's own readers, so what the upload is said to be is what a
worker will find. The engine (numpy, OpenCV) is imported on the first upload, not when the API
starts. A file that is neither a photo the engine reads nor a video is :class:`Unsupported`,
named by what it looks like. A JPEG, PNG or WebP photo cut short (its header whole, the rest
missing: a copy interrupted) is found as it streams past (:class:`ImageEnd`) and refused too, and
so is a PNG whose image data stops short of its pixels though its chunks end properly.
"""

from __future__ import annotations

import math
import os
import zlib
from typing import Any

from prismcore.io import HEAD_BYTES, video_container

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


_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # by colour type: grey, RGB, palette, grey+alpha, RGBA
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))
_INFLATE_STEP = 1 << 20  # the PNG's pixels are inflated this many bytes at a time, and dropped


def _png_pixel_bytes(ihdr: bytes) -> int | None:
    """The bytes a PNG's image data inflates to (each row's filter byte included), from its IHDR;
    None for a header this check does not know."""
    if len(ihdr) < 13:
        return None
    width, height = int.from_bytes(ihdr[0:4], "big"), int.from_bytes(ihdr[4:8], "big")
    depth, colour, interlace = ihdr[8], ihdr[9], ihdr[12]
    if colour not in _PNG_CHANNELS or interlace not in (0, 1):
        return None
    bits = depth * _PNG_CHANNELS[colour]

    def rows(w: int, h: int) -> int:
        return h * (1 + math.ceil(w * bits / 8)) if w and h else 0

    if interlace == 0:
        return rows(width, height)
    return sum(rows(math.ceil(max(width - x0, 0) / dx), math.ceil(max(height - y0, 0) / dy))
               for x0, y0, dx, dy in _ADAM7)


def _bmp_end(head: bytes) -> int:
    """Where a BMP's pixels end: their offset plus the rows its header's size and depth take
    (uncompressed or bit fields), or the image size it states (compressed); 0 when unknown."""
    if len(head) < 26:
        return 0
    le = lambda a, b: int.from_bytes(head[a:b], "little")  # noqa: E731
    offset, dib = le(10, 14), le(14, 18)
    if dib == 12:  # BITMAPCOREHEADER
        width, height, bits, compression, stated = le(18, 20), le(20, 22), le(24, 26), 0, 0
    elif dib >= 40 and len(head) >= 38:
        width = abs(int.from_bytes(head[18:22], "little", signed=True))
        height = abs(int.from_bytes(head[22:26], "little", signed=True))
        bits, compression, stated = le(28, 30), le(30, 34), le(34, 38)
    else:
        return 0
    if compression in (0, 3, 6) and bits in (1, 2, 4, 8, 16, 24, 32):
        return offset + (width * bits + 31) // 32 * 4 * height
    return offset + stated if stated else 0


_HEADER_KEEP = 1 << 20  # a BMP's or TIFF's bytes read for its header and first directory
_TIFF_DATA = {273: 279, 324: 325}  # StripOffsets -> StripByteCounts, TileOffsets -> TileByteCounts
_TIFF_SIZES = {3: 2, 4: 4, 16: 8}  # SHORT, LONG, LONG8


def _tiff_end(head: bytes) -> int:
    """How far a TIFF must reach: past its first image directory and, when that directory lies
    in `head`, past the strips or tiles it lists; 0 when unknown (BigTIFF, a bad offset)."""
    order: Any = "little" if head[:2] == b"II" else "big"
    ifd = int.from_bytes(head[4:8], order)
    if ifd < 8:
        return 0
    if ifd + 2 > len(head):
        return ifd + 2  # the directory lies past the bytes kept: its own start is checked
    count = int.from_bytes(head[ifd : ifd + 2], order)
    end = ifd + 2 + 12 * count + 4
    if end > len(head):
        return end
    values: dict[int, list[int]] = {}
    for k in range(count):
        entry = head[ifd + 2 + 12 * k : ifd + 14 + 12 * k]
        tag, kind, n = (int.from_bytes(entry[0:2], order), int.from_bytes(entry[2:4], order),
                        int.from_bytes(entry[4:8], order))
        size = _TIFF_SIZES.get(kind)
        if size is None or tag not in (*_TIFF_DATA, *_TIFF_DATA.values()):
            continue
        at = 8 if n * size <= 4 else int.from_bytes(entry[8:12], order)
        source = entry if n * size <= 4 else head
        if at + n * size > len(source):
            continue  # the list lies past the bytes kept: not checked here
        values[tag] = [int.from_bytes(source[at + i * size : at + (i + 1) * size], order) for i in range(n)]
    for offsets, counts in _TIFF_DATA.items():
        if offsets in values and counts in values and len(values[offsets]) == len(values[counts]):
            end = max(end, *(o + c for o, c in zip(values[offsets], values[counts], strict=True)))
    return end


class ImageEnd:
    """Fed a photo's bytes as they pass, says whether the photo's end was in them.

    A JPEG ends at the end-of-image marker that follows its scans (the segments are walked by
    their lengths, the entropy-coded data scanned for its next marker: an EXIF thumbnail's own
    marker, or data appended after the image, as motion photos have, are not mistaken for it);
    a PNG at its IEND chunk (the chunks walked by their lengths), its image data (the IDAT
    chunks) inflated on the way, a megabyte at a time and dropped, to the end of its zlib stream
    and as many bytes as its header's pixels take (a PNG whose data was cut short and its
    chunks closed after it is cut short too). Data that does not inflate is left for the worker
    to report as damaged, and a PNG over `max_pixels` for the worker to refuse as too large: it
    is not inflated, nor is data past the pixels' bytes, so a decompression bomb costs nothing
    here. A WebP ends where its RIFF header's size says; a BMP where its pixels end (their
    offset, plus the rows its header's size and depth take); a TIFF past its first image
    directory and the strips or tiles that directory points to (what of it lies in the bytes
    kept at the start: a directory written after the pixels is checked for its own end only).
    """

    def __init__(self, head: bytes, max_pixels: int | None = None) -> None:
        self.format = ("JPEG" if head.startswith(b"\xff\xd8\xff") else
                       "PNG" if head.startswith(b"\x89PNG\r\n\x1a\n") else
                       "WEBP" if head[:4] == b"RIFF" and head[8:12] == b"WEBP" else
                       "BMP" if head.startswith(b"BM") else
                       "TIFF" if head[:4] in (b"II*\x00", b"MM\x00*") else None)
        self.size = 0
        self.ended = self.format is None  # nothing to check
        self._buf = b""
        self._skip = 2 if self.format == "JPEG" else 8 if self.format == "PNG" else 0  # SOI, signature
        self._entropy = False
        self._riff = int.from_bytes(head[4:8], "little") + 8 if self.format == "WEBP" else 0
        # A BMP's or TIFF's first bytes (the first feed may be a few bytes of a multipart body),
        # read for where the file must reach once every byte was fed.
        self._head = b""
        self._needed = 0
        # A PNG's image data: its bytes still to come in the current IDAT chunk, the stream
        # inflating it (None when not checked: it does not inflate, the image is over
        # `max_pixels`, or its pixels' bytes were all seen), the bytes it gave and those expected.
        self._max_pixels = max_pixels
        self._idat = 0
        self._inflater: Any = zlib.decompressobj() if self.format == "PNG" else None
        self._pixels = 0
        self._expected: int | None = None
        self._short_data = False

    def feed(self, data: bytes) -> None:
        self.size += len(data)
        if self.ended:
            return
        if self.format == "WEBP":
            self.ended = self.size >= self._riff
            return
        if self.format in ("BMP", "TIFF"):
            self._head += data[: max(_HEADER_KEEP - len(self._head), 0)]
            return
        if self._idat:  # the rest of an IDAT chunk, then its CRC
            n = min(self._idat, len(data))
            self._inflate(data[:n])
            self._idat -= n
            data = data[n:]
            if self._idat:
                return
            self._skip = 4
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
                self._short_data = self._inflater is not None
                return len(buf)
            end = i + 12 + length
            if kind == b"IHDR":
                if end > len(buf):
                    return i  # a few bytes: wait for the whole chunk
                ihdr = buf[i + 8 : i + 8 + length]
                self._expected = _png_pixel_bytes(ihdr)
                pixels = int.from_bytes(ihdr[0:4], "big") * int.from_bytes(ihdr[4:8], "big")
                if self._expected is None or (self._max_pixels is not None and pixels > self._max_pixels):
                    self._inflater = None
            elif kind == b"IDAT":
                data = buf[i + 8 : min(i + 8 + length, len(buf))]
                self._inflate(data)
                if len(data) < length:  # the rest of its data comes in the next feeds
                    self._idat = length - len(data)
                    return len(buf)
            if end > len(buf):
                self._skip = end - len(buf)
                return len(buf)
            i = end
        return i

    def _inflate(self, data: bytes) -> None:
        """Inflate `data`, part of the PNG's image data, counting the bytes it gives, until they
        are as many as its pixels take."""
        if self._expected is None:  # image data before its header: for the worker to report
            self._inflater = None
        try:
            while data and self._inflater is not None and not self._inflater.eof:
                self._pixels += len(self._inflater.decompress(data, _INFLATE_STEP))
                data = self._inflater.unconsumed_tail
                if self._expected is not None and self._pixels >= self._expected:
                    self._inflater = None  # every pixel is there
        except zlib.error:
            self._inflater = None  # damaged, not cut short: for the worker to report

    def problem(self, name: str) -> str | None:
        """Why the photo is cut short, once every byte was fed; None when it is whole."""
        if self.format in ("BMP", "TIFF"):
            self._needed = _bmp_end(self._head) if self.format == "BMP" else _tiff_end(self._head)
            self.ended = self.size >= self._needed  # 0: the header does not tell, taken as whole
        if self.ended and not self._short_data:
            return None
        if self._short_data:
            return (f"{name!r} is a truncated {self.format} ({self.size:,} bytes, its image data cut short: "
                    f"{self._pixels:,} of the {self._expected or 0:,} bytes of pixels its header announces): "
                    "the file was not written whole; upload the complete photo")
        end = {"JPEG": "its end-of-image marker", "PNG": "its IEND chunk",
               "WEBP": f"the {self._riff:,} bytes its header announces",
               "BMP": f"the {self._needed:,} bytes its header's pixels take",
               "TIFF": f"the {self._needed:,} bytes its image directory points to"}[self.format or ""]
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
    from prismcore.io import probe_image, sniff_format

    label = repr(name)
    try:
        fmt = sniff_format(head, label)
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
    from prismcore.io import probe_video

    container = (video_container(head[:HEAD_BYTES]) or "video").upper()
    try:
        info = probe_video(path)
    except InputError as exc:
        # The engine names the file by its path: the client knows it by its name.
        return {"kind": "video", "format": container,
                "error": str(exc).replace(repr(str(path)), repr(name))}
    return {"kind": "video", "format": container, "width": info.width, "height": info.height,
            "frame_count": info.frame_count, "fps": round(info.fps, 6), "codec": info.codec}

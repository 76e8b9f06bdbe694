"""Safe decoding of input photos (BMP, PNG, JPEG, TIFF, WebP) into RGB arrays.

:func:`load_image` turns a file path or the bytes of an image into an RGB array of shape
(H, W, 3): ``uint8`` for 8-bit images, ``float32`` in 0..255 units (value / 257) for 16-bit
PNG and TIFF so the extra precision is kept. :func:`probe_image` reads the header only.

Everything a caller can get wrong raises :class:`~prismcore.errors.InputError` with a one-line
message quoting the file name (or ``name=``), the size or the format at fault:

* The format is recognised from the content, never from the file name, and only the five
  formats above are handed to a decoder: the one format's Pillow plugin is called directly, so
  no other plugin ever parses untrusted bytes. ``Image.open(fp, formats=[...])`` restricts the
  plugins the same way but does not do this job: it applies Pillow's global bomb limit while
  opening (a 100000 x 100000 PNG header raises DecompressionBombError before its size can be
  reported against ``max_pixels``, or probed), and it replaces a plugin's reason for refusing
  a damaged header with "cannot identify image file <_io.BytesIO object at 0x...>".
* Decompression bombs: the dimensions are read from the header first (by Pillow's lazy open, or
  by our own parse for WebP, whose Pillow open already allocates the canvas), and an image of
  more than ``max_pixels`` pixels is refused before anything of its size is allocated.
* Truncated or corrupt files are refused, never returned as a partial image. Pixels are decoded
  by Pillow, which raises on missing data as long as ``PIL.ImageFile.LOAD_TRUNCATED_IMAGES``
  keeps its default (False; this module never changes it) and keeps libjpeg's and libpng's
  messages off stderr (OpenCV prints them, and depending on its version returns a cut JPEG with
  a grey tail). Where Pillow would only *warn*, or accept a cut file, this module checks the
  structure itself first: a TIFF's first directory, the EXIF/GPS directories it points to, and
  its strip and tile ranges; a PNG's chunk chain up to IEND; a WebP's RIFF length.
* EXIF orientation (JPEG APP1, PNG eXIf, WebP EXIF, the TIFF Orientation tag) is applied, so the
  array is upright the way a browser shows the photo. EXIF blocks are read by this module, and a
  malformed one is ignored; Pillow is given a JPEG whose EXIF segments are renamed, because its
  own EXIF reader warns on a malformed block while opening the file. Pillow's reader
  (``getexif``, ``Image.Exif``) is not used for the orientation: one tag's data past the end
  of the block (``OSError("Truncated File Read")``) makes it drop the whole directory, the
  Orientation tag with it, where browsers still turn the photo. ``ImageOps.exif_transpose`` is
  not used either: the turn here is a view of the array (no copy), and the 16-bit colour path
  has no Pillow image to turn.

Known gap: damaged *compressed data* inside a complete file is found only as far as the codec
finds it. A JPEG with scrambled entropy-coded data decodes to scrambled pixels without an error
(libjpeg only counts warnings), and libtiff reports bad LZW/Deflate data through its
process-wide handler, which prints to stderr (the file is still refused). The structure checks
and the header parsers are `prismcore.io.image_structure`.

Nothing global is changed: Pillow's ``MAX_IMAGE_PIXELS`` is left alone (its check in
``Image.open`` is bypassed by opening with the format's plugin class), and no warning filter is
touched, except in one case: when ``max_pixels`` is raised above Pillow's own limit (about
89 Mpx) and an image exceeds the latter, the decode runs inside ``warnings.catch_warnings``
to silence Pillow's bomb warning; beyond twice Pillow's limit Pillow refuses (an InputError).

Speed: an 8-bit image is decoded once, by Pillow (libjpeg-turbo, libpng, libwebp, libtiff), then
copied once into the numpy result. Only 16-bit colour images, which Pillow cannot decode at
full depth, are decoded twice: by Pillow to prove the file complete, then by OpenCV at 16 bits.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import operator
import os
import struct
import warnings
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import BinaryIO

import cv2
import numpy as np
from PIL import (
    BmpImagePlugin,
    Image,
    ImageFile,
    JpegImagePlugin,
    PngImagePlugin,
    TiffImagePlugin,
    WebPImagePlugin,
)

from prismcore.errors import InputError
from prismcore.io.containers import video_container
from prismcore.io.image_structure import (
    _TIFF_WANTED,
    _check_png_chunks,
    _check_tiff_ranges,
    _corrupt,
    _CorruptError,
    _exif_orientation,
    _tiff_ifd0,
    _valid_orientation,
    _webp_header,
    jpeg_header,
)

__all__ = ["DEFAULT_MAX_PIXELS", "FORMATS", "PIL_ERRORS", "ImageInfo", "load_image",
           "probe_image", "sniff_format"]

DEFAULT_MAX_PIXELS = 50_000_000
"""Largest image (width * height) :func:`load_image` decodes unless told otherwise."""

FORMATS = ("BMP", "PNG", "JPEG", "TIFF", "WEBP")
"""Formats :func:`load_image` and :func:`probe_image` accept, as :attr:`ImageInfo.format` names them."""

Source = str | os.PathLike[str] | bytes | bytearray | memoryview

_PLUGINS: dict[str, type[ImageFile.ImageFile]] = {
    "BMP": BmpImagePlugin.BmpImageFile,
    "PNG": PngImagePlugin.PngImageFile,
    "JPEG": JpegImagePlugin.JpegImageFile,
    "TIFF": TiffImagePlugin.TiffImageFile,
    "WEBP": WebPImagePlugin.WebPImageFile,
}
# What Pillow raises for a damaged file while opening or decoding it (ImageFile wraps parser
# slips in SyntaxError; decoders raise OSError; zlib and struct errors can escape from plugins).
PIL_ERRORS = (
    OSError,
    SyntaxError,
    ValueError,
    EOFError,
    struct.error,
    zlib.error,
    IndexError,
    KeyError,
    TypeError,
    NotImplementedError,
)
_GRAY16_MODES = frozenset({"I;16", "I;16L", "I;16B", "I;16N"})
_OTHER_FORMATS = (  # recognised only to say what a refused file is
    (b"GIF87a", "GIF"),
    (b"GIF89a", "GIF"),
    (b"%PDF", "PDF"),
    (b"\x00\x00\x00\x0cJXL ", "JPEG XL"),
    (b"\xff\x0a", "JPEG XL"),
    (b"\x00\x00\x00\x0cjP  ", "JPEG 2000"),
)


@dataclass(frozen=True)
class ImageInfo:
    """What an image file's header says, as :func:`probe_image` reads it.

    Attributes
    ----------
    width, height : int
        Stored pixel size, before EXIF orientation (the size the decompression-bomb limit
        applies to).
    format : str
        One of :data:`FORMATS`: "BMP", "PNG", "JPEG", "TIFF" or "WEBP".
    mode : str
        Pillow's name for the stored pixel layout: "RGB", "RGBA", "L" (grayscale), "LA", "P"
        (palette), "1" (bilevel), "CMYK", "I;16" (16-bit grayscale), ... A 16-bit colour file is
        "RGB" or "RGBA" with ``bit_depth`` 16.
    bit_depth : int
        Bits per sample as decoded: 8 (also for 1-, 2-, 4-bit and palette images), 16 (16-bit
        PNG and TIFF, returned as float32) or 32 (32-bit TIFF, which :func:`load_image` refuses).
    orientation : int
        EXIF orientation 1..8 (1 = upright; anything missing or invalid counts as 1).
    chroma : str or None
        A colour JPEG's colour sampling: "4:4:4" (whole), "4:2:2" (halved across) or "4:2:0"
        (halved both ways: a phone's and most cameras' default); None for another format, a grey
        JPEG or another layout.
    """

    width: int
    height: int
    format: str
    mode: str
    bit_depth: int
    orientation: int = 1
    chroma: str | None = None

    @property
    def pixels(self) -> int:
        """width * height."""
        return self.width * self.height

    @property
    def shape(self) -> tuple[int, int, int]:
        """Shape (H, W, 3) of the array :func:`load_image` returns (after orientation)."""
        if self.orientation >= 5:  # 5..8 turn the image by 90 degrees
            return self.width, self.height, 3
        return self.height, self.width, 3

    @property
    def dtype(self) -> np.dtype:
        """dtype :func:`load_image` returns: uint8, or float32 for 16-bit images."""
        return np.dtype(np.float32 if self.bit_depth == 16 else np.uint8)


# --------------------------------------------------------------------------------------------
# public API


def load_image(
    source: Source, *, max_pixels: int = DEFAULT_MAX_PIXELS, name: str | None = None
) -> np.ndarray:
    """Decode an image file into an upright RGB array.

    Parameters
    ----------
    source : str, os.PathLike or bytes
        Path of the file, or its content (bytes, bytearray or memoryview). The format is told
        from the content (BMP, PNG, JPEG, TIFF or WebP), whatever the file name says.
    max_pixels : int, default DEFAULT_MAX_PIXELS
        Largest width * height accepted; checked from the header before decoding.
    name : str, optional
        Name used in error messages (e.g. the uploaded file name when ``source`` is bytes or a
        temporary path).

    Returns
    -------
    ndarray, shape (H, W, 3)
        RGB (never BGR), C-contiguous, writable and owned by the caller. dtype uint8 for 8-bit
        images; float32 in 0..255 units (16-bit value / 257, so 65535 -> 255.0) for 16-bit PNG
        and TIFF. Grayscale is replicated into the three channels, alpha is dropped (not
        composited), palette, bilevel and CMYK images are converted to RGB. The EXIF orientation
        is applied, so H and W are the displayed height and width; the first frame is returned
        for multi-frame files.

    Raises
    ------
    InputError
        Missing, unreadable or empty file; not an image or not one of the five formats; more
        than ``max_pixels`` pixels; truncated or corrupt data; a 32-bit or otherwise unsupported
        pixel layout; ``source`` or ``max_pixels`` of the wrong type.
    """
    limit = _check_limit(max_pixels)
    data, label = _read_all(source, name)
    info, im, tags = _inspect(data, io.BytesIO(data), label, whole=True)
    if info.pixels > limit:
        raise InputError(
            f"{label} is {info.width}x{info.height} = {info.pixels} pixels, over the limit of {limit} pixels"
        )
    if info.format == "TIFF":
        _check_tiff_ranges(tags, len(data), label)
    elif info.format == "PNG":
        _check_png_chunks(data, label)
    if im is None:  # WebP: opened only now that its size is known to be acceptable
        im = _pil_open(info.format, io.BytesIO(data), label)
    colour16 = info.bit_depth == 16 and im.mode in ("RGB", "RGBA")
    # (older Pillow versions open 16-bit grayscale PNG as mode "I")
    gray16 = info.bit_depth == 16 and im.mode in _GRAY16_MODES | {"I"}
    if info.bit_depth != 8 and not (colour16 or gray16):
        raise InputError(
            f"{label} has {info.bit_depth}-bit samples in mode {im.mode!r}; "
            "only 8- and 16-bit images are supported"
        )
    _pil_load(im, info, label)
    orientation = info.orientation
    if info.format == "TIFF" and not colour16 and 274 not in getattr(im, "tag_v2", {274: 0}):
        # Recent Pillow turns a TIFF upright while loading it, then drops the Orientation tag;
        # older versions leave both the pixels and the tag alone.
        orientation = 1

    planes: np.ndarray
    if colour16:
        # Pillow decodes 16-bit colour to 8 bits (it has already proved the file complete), so
        # decode again with OpenCV, which keeps 16 bits. IMREAD_UNCHANGED keeps the depth and
        # the channels, and ignores EXIF orientation (applied below, as for every format).
        decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if decoded is None or decoded.shape[:2] != (info.height, info.width) or decoded.dtype != np.uint16:
            raise InputError(f"{label} is truncated or corrupt ({info.format}: 16-bit decode failed)")
        planes = decoded
        if planes.ndim == 3 and planes.shape[2] in (3, 4):
            # OpenCV returns channels in BGR(A) order; convert to RGB, dropping alpha.
            code = cv2.COLOR_BGRA2RGB if planes.shape[2] == 4 else cv2.COLOR_BGR2RGB
            planes = cv2.cvtColor(planes, code)
        elif planes.ndim == 3:  # gray (+ alpha)
            planes = planes[..., 0]
    elif gray16:
        planes = np.asarray(im)  # uint16 (any byte order), or int32 holding 0..65535 for "I"
    else:
        planes = _rgb_or_gray8(im)

    planes = _orient(planes, orientation)
    if info.bit_depth == 16:
        planes = planes.astype(np.float32, order="C")
        planes /= np.float32(257.0)
    if planes.ndim == 2:  # grayscale: the same value in R, G and B
        out = np.empty((*planes.shape, 3), dtype=planes.dtype)
        out[...] = planes[..., None]
        return out
    out = np.ascontiguousarray(planes)
    return out if out.flags.writeable else out.copy()


def probe_image(source: Source, *, name: str | None = None) -> ImageInfo:
    """Read an image's size, format, pixel layout and orientation from its header.

    Nothing is decoded and, for a path, only the parts of the file the header parse touches are
    read (the file is memory-mapped), so this is safe and fast on decompression bombs.

    Parameters
    ----------
    source : str, os.PathLike or bytes
        Path of the file, or its content.
    name : str, optional
        Name used in error messages.

    Returns
    -------
    ImageInfo
        ``info.shape`` and ``info.dtype`` are what :func:`load_image` would return.

    Raises
    ------
    InputError
        Missing, unreadable or empty file; not one of the five formats; an unreadable header.
        Damage after the header is found only by :func:`load_image`.
    """
    with _mapped(source, name) as (buf, fp, label):
        info, _, _ = _inspect(buf, fp, label, whole=False)
    return info


# --------------------------------------------------------------------------------------------
# reading the source


def _check_limit(max_pixels: int) -> int:
    try:
        if isinstance(max_pixels, bool):
            raise TypeError
        limit = operator.index(max_pixels)
    except TypeError:
        raise InputError(f"max_pixels must be an integer, got {max_pixels!r}") from None
    if limit < 1:
        raise InputError(f"max_pixels must be at least 1, got {limit}")
    return limit


def _path_label(source: object, name: str | None) -> tuple[str | bytes, str]:
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(
            f"image source must be a path or bytes, got {type(source).__name__}"
            + (f" for {name!r}" if name else "")
        )
    path = os.fspath(source)
    return path, repr(name if name is not None else path)


def _read_error(path: str | bytes, label: str, exc: OSError | ValueError) -> InputError:
    if isinstance(exc, ValueError):
        return InputError(f"image path {label} is not a valid path ({exc})")
    if isinstance(exc, FileNotFoundError):
        return InputError(f"image file {label} does not exist")
    if isinstance(exc, IsADirectoryError) or os.path.isdir(path):
        return InputError(f"image file {label} is a directory")
    return InputError(f"cannot read image file {label}: {exc.strerror or exc}")


def _read_all(source: Source, name: str | None) -> tuple[bytes, str]:
    """The whole content and the label for messages."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        data = bytes(source)
        label = repr(name) if name is not None else f"image data ({len(data)} bytes)"
    else:
        path, label = _path_label(source, name)
        try:
            with open(path, "rb") as f:
                data = f.read()
        except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
            raise _read_error(path, label, exc) from exc
    if not data:
        raise InputError(f"{label} is empty (0 bytes)")
    return data, label


@contextlib.contextmanager
def _mapped(source: Source, name: str | None) -> Iterator[tuple[bytes | mmap.mmap, BinaryIO, str]]:
    """Content as a bytes-like object (a read-only map for files), a file object and the label."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        data, label = _read_all(source, name)
        yield data, io.BytesIO(data), label
        return
    path, label = _path_label(source, name)
    try:
        f = open(path, "rb")  # noqa: SIM115 (closed below, after the map)
    except (OSError, ValueError) as exc:
        raise _read_error(path, label, exc) from exc
    with f:
        try:
            size = os.fstat(f.fileno()).st_size
            buf: bytes | mmap.mmap = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
        except (OSError, ValueError):  # not mappable (a pipe, a special file): read it
            buf = f.read()
        if not buf:
            raise InputError(f"{label} is empty (0 bytes)")
        try:
            f.seek(0)
            yield buf, f, label
        finally:
            if isinstance(buf, mmap.mmap):
                buf.close()


# --------------------------------------------------------------------------------------------
# header inspection


def sniff_format(buf: bytes | mmap.mmap, label: str) -> str:
    """The photo format (one of FORMATS) a file's first bytes show; InputError naming `label` when
    they show none of them."""
    head = bytes(buf[:16])
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "PNG"
    if head.startswith(b"\xff\xd8\xff"):
        return "JPEG"
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "TIFF"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "WEBP"
    if head.startswith(b"BM"):
        return "BMP"
    container = video_container(head)
    if container:
        raise InputError(f"{label} is a video ({container.upper()}), not a photo: select its frames "
                         "to measure them (frames in the spec)")
    kind = next((k for magic, k in _OTHER_FORMATS if head.startswith(magic)), None)
    if head[4:8] == b"ftyp":
        kind = "HEIF/AVIF (" + head[8:12].decode("latin-1").strip() + ")"
    if kind:
        raise InputError(f"{label} is a {kind} image; supported formats are BMP, PNG, JPEG, TIFF, WebP")
    raise InputError(f"{label} is not a BMP, PNG, JPEG, TIFF or WebP image (it starts with {head[:8]!r})")


def _bomb(label: str, size: tuple[int, int], exc: Exception) -> InputError:
    w, h = size
    return InputError(
        f"{label} is {w}x{h} = {w * h} pixels, over Pillow's decompression-bomb limit "
        f"of {Image.MAX_IMAGE_PIXELS} pixels ({exc.__class__.__name__})"
    )


def _pil_open(fmt: str, fp: BinaryIO, label: str) -> ImageFile.ImageFile:
    """Pillow's lazy open of one known format: reads the header, decodes nothing.

    The plugin class is used directly instead of ``Image.open``: no other plugin gets to parse
    the bytes, and ``Image.open``'s bomb warning (ruled by Pillow's global limit, not ours) is
    not triggered; our own limit is checked by the caller.
    """
    try:
        return _PLUGINS[fmt](fp)
    except Image.DecompressionBombError as exc:  # WebP checks its canvas while opening
        raise InputError(f"{label} is over Pillow's decompression-bomb limit ({exc})") from exc
    except PIL_ERRORS as exc:
        raise _corrupt(label, fmt, exc) from exc


def _pil_load(im: ImageFile.ImageFile, info: ImageInfo, label: str) -> None:
    """Decode the pixels; damage raises (Pillow's LOAD_TRUNCATED_IMAGES is left False)."""
    ceiling = Image.MAX_IMAGE_PIXELS
    try:
        if ceiling is not None and info.pixels > ceiling:
            # Only reachable when the caller raised max_pixels above Pillow's own limit: TIFF
            # loading re-checks Pillow's limit and would warn (or raise, beyond twice it).
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                im.load()
        else:
            im.load()
    except Image.DecompressionBombError as exc:
        raise _bomb(label, im.size, exc) from exc
    except PIL_ERRORS as exc:
        raise _corrupt(label, info.format, exc) from exc


def _inspect(
    buf: bytes | mmap.mmap, fp: BinaryIO, label: str, *, whole: bool
) -> tuple[ImageInfo, ImageFile.ImageFile | None, dict[int, np.ndarray]]:
    """ImageInfo from the header, the lazily opened Pillow image (None for WebP) and, for
    TIFF, the integer tags of the first directory.

    ``fp`` reads the same bytes as ``buf``; ``whole`` says the Pillow image will be decoded, so
    a JPEG must be handed over complete rather than up to its first scan.
    """
    fmt = sniff_format(buf, label)
    tags: dict[int, np.ndarray] = {}
    orientation = 1
    if fmt == "WEBP":
        width, height, alpha, exif = _webp_header(buf, label)
        info = ImageInfo(width, height, fmt, "RGBA" if alpha else "RGB", 8, _exif_orientation(exif))
        return info, None, tags
    if fmt == "JPEG":
        header_end, idents, exif = jpeg_header(buf)
        orientation = _exif_orientation(exif)
        if idents or not whole:
            # Pillow parses a JPEG's EXIF block while opening it (for a dpi value) and only
            # *warns* if the block is malformed. The block is read here instead, and Pillow gets
            # a copy in which each EXIF segment is renamed, which it skips.
            head = bytearray(buf[: len(buf) if whole else header_end])
            for at in idents:
                if at + 4 <= len(head):
                    head[at : at + 4] = b"ExiF"
            fp = io.BytesIO(head)
    if fmt == "TIFF":
        try:
            tags = _tiff_ifd0(buf, _TIFF_WANTED)
        except _CorruptError as exc:
            raise _corrupt(label, fmt, exc) from None
    im = _pil_open(fmt, fp, label)
    width, height = im.size
    depth = 8
    if fmt == "PNG":
        depth = 16 if buf[24] == 16 else 8  # IHDR bit depth (Pillow has checked the IHDR chunk)
        orientation = _exif_orientation(im.info.get("exif"))  # an eXIf chunk before IDAT
    elif fmt == "TIFF":
        # Recent Pillow reports a TIFF's size already turned by its Orientation tag: use the tags.
        width, height = (int(tags[t][0]) if t in tags and tags[t].size else 0 for t in (256, 257))
        bits = int(tags[258].max()) if 258 in tags and tags[258].size else 1
        depth = 8 if bits <= 8 else 16 if bits <= 16 else 32
        if 274 in tags and tags[274].size:
            orientation = _valid_orientation(int(tags[274][0]))
    chroma = _CHROMA.get(JpegImagePlugin.get_sampling(im)) if fmt == "JPEG" and im.mode == "RGB" else None
    return ImageInfo(width, height, fmt, im.mode, depth, orientation, chroma), im, tags


_CHROMA = {0: "4:4:4", 1: "4:2:2", 2: "4:2:0"}  # Pillow's numbers for a JPEG's colour sampling


# --------------------------------------------------------------------------------------------
# pixels


def _rgb_or_gray8(im: ImageFile.ImageFile) -> np.ndarray:
    """8-bit pixels of a loaded image as (H, W, 3) RGB or (H, W) gray; may be a read-only view."""
    mode = im.mode
    if mode in ("RGB", "L"):
        return np.asarray(im)
    if mode in ("RGBA", "RGBX", "RGBa"):
        return np.asarray(im)[..., :3]
    if mode in ("LA", "La"):
        return np.asarray(im)[..., 0]
    if mode in ("P", "PA"):
        # via RGBA: Pillow warns when converting a palette with transparency straight to RGB
        return np.asarray(im.convert("RGBA"))[..., :3]
    if mode == "1":
        return np.asarray(im.convert("L"))
    return np.asarray(im.convert("RGB"))  # CMYK, YCbCr, LAB, ...


def _orient(a: np.ndarray, orientation: int) -> np.ndarray:
    """View of ``a`` (H, W[, C]) turned upright for EXIF ``orientation`` 1..8."""
    if orientation == 2:  # mirrored left-right
        return a[:, ::-1]
    if orientation == 3:  # rotated 180
        return a[::-1, ::-1]
    if orientation == 4:  # mirrored top-bottom
        return a[::-1]
    t = a.swapaxes(0, 1)
    if orientation == 5:  # transpose
        return t
    if orientation == 6:  # stored turned 90 counter-clockwise: turn 90 clockwise
        return t[:, ::-1]
    if orientation == 7:  # transverse
        return t[::-1, ::-1]
    if orientation == 8:  # stored turned 90 clockwise: turn 90 counter-clockwise
        return t[::-1]
    return a

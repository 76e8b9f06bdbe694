"""The camera's focal length in pixels, from a photo's EXIF data.

:func:`read_camera_exif` reads the few EXIF fields that say what camera took a photo and how long
its lens was; :func:`focal_px_from_exif` turns them into a focal length in pixels of the image as
:func:`prismcore.io.images.load_image` decodes it (or says why it cannot); :func:`camera_key` names
the camera so photos taken with one camera and lens setting can share one focal length.

EXIF blocks are parsed by Pillow (``PIL.Image.Exif``); this module only finds the block in the
file (JPEG APP1, PNG eXIf, WebP EXIF chunk, or the TIFF file itself), never decodes pixels, and
treats whatever Pillow cannot read, or reads as nonsense, as missing.

Two ways to a focal length, in this order of trust:

1. ``FocalLengthIn35mmFilm`` (f35, mm): the focal length a 36 x 24 mm film camera would need for
   the same angle of view. The standard definition (CIPA DC-008 refers to the angle of view; the
   crop factor is the ratio of diagonals) matches *diagonals*, so
   ``f_px = f35 / 43.2667 * hypot(W, H)`` with 43.2667 mm = hypot(36, 24) and W x H the decoded
   size in px. It is preferred because phones write it right, including their digital zoom
   (a 2x digital zoom writes twice the f35 and upsamples the crop to the full pixel size, while
   ``FocalLength`` stays the lens's own), and it needs no sensor size.
2. ``FocalLength`` (mm) with ``FocalPlaneXResolution`` (pixels per ``FocalPlaneResolutionUnit``
   on the sensor, for the image of ``PixelXDimension`` px width):
   ``f_px = f_mm * px_per_mm * decoded_width / original_width``, widths taken in the stored
   (unrotated) frame.

Orientation: :func:`~prismcore.io.images.load_image` applies the EXIF orientation, so for
orientations 5..8 (turned by 90 degrees) the decoded width is the stored height. The orientation
used here is the one :func:`~prismcore.io.images.probe_image` reads, the same reading
``load_image`` turns the pixels by, so the two cannot disagree even on a malformed block.
Without ``PixelXDimension``/``PixelYDimension`` the decoded image is assumed to be the photo as
taken (the basis says so).

Either result is refused (a :class:`NoExifFocal` with the reason, or None) when the decoded
image is not the photo as taken resized uniformly (its aspect ratio differs from
``PixelXDimension`` x ``PixelYDimension`` by more than 1 % plus one pixel's rounding: cropped,
so the angle of view the EXIF describes is not this image's), when the focal plane's X and Y
resolutions differ by more than 1 % (non-square pixels, which the pinhole model here does not
have), or when the result is outside ``[0.2, 10]`` x the image diagonal (an 8.7 mm to 433 mm
lens in 35 mm terms: beyond that the EXIF is wrong more often than the lens is that extreme).
An implausible 35 mm value falls through to the focal plane route, whose basis then says so.
"""

from __future__ import annotations

import math
import operator
import re
import struct
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from PIL import Image

from prismcore.errors import InputError
from prismcore.io.image_structure import jpeg_header
from prismcore.io.images import PIL_ERRORS, probe_image

__all__ = [
    "FILM_35MM_DIAGONAL_MM",
    "CameraExif",
    "ExifFocal",
    "NoExifFocal",
    "camera_key",
    "exif_focal",
    "explain_exif_focal",
    "focal_px_from_exif",
    "read_camera_exif",
]

FILM_35MM_DIAGONAL_MM = math.hypot(36.0, 24.0)
"""Diagonal of the 36 x 24 mm frame, 43.2667 mm: the length a 35 mm-equivalent focal length is
scaled against."""

# IFD0
_MAKE, _MODEL, _ORIENTATION, _EXIF_IFD = 0x010F, 0x0110, 0x0112, 0x8769
# Exif IFD
_FOCAL_LENGTH, _PIXEL_X, _PIXEL_Y, _FOCAL_35MM, _LENS_MODEL = 0x920A, 0xA002, 0xA003, 0xA405, 0xA434
_FP_XRES, _FP_YRES, _FP_UNIT = 0xA20E, 0xA20F, 0xA210
# TIFF/EP (raw and some TIFF files) numbers the focal plane tags differently, in IFD0.
_EP_FP_XRES, _EP_FP_YRES, _EP_FP_UNIT = 0x920E, 0x920F, 0x9210

_MM_PER_UNIT = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch, cm, and TIFF/EP's mm and micrometre
_UNIT_NAMES = {2: "in", 3: "cm", 4: "mm", 5: "um"}

EXIF_HEAD_BYTES = 256 * 1024
"""How much of a photo file's start to read for its EXIF: a JPEG's APP1 segment is at most 64 KiB
and comes before the image data (a PNG's eXIf chunk past this is not found: the focal length is
then fitted, and the report says so)."""

_ASPECT_TOLERANCE = 0.01  # relative aspect mismatch still read as the same photo resized
_PLAUSIBLE_FOCAL_DIAGONALS = (0.2, 10.0)  # f_px / image diagonal px
_MAX_TEXT = 128  # longer make/model strings are a broken block; they are cut, not trusted further

# What Pillow may raise on a malformed EXIF block, while loading it or reading a value lazily.
_PIL_ERRORS = (*PIL_ERRORS, AttributeError, ZeroDivisionError, OverflowError, RecursionError)


@dataclass(frozen=True)
class CameraExif:
    """What a photo's EXIF says about the camera that took it.

    Every field the file lacks, or holds as nonsense (zero, negative, not finite, a zero
    denominator, the wrong type), is None.

    Attributes
    ----------
    make, model, lens_model : str or None
        ``Make``, ``Model`` and ``LensModel``, stripped of padding and control characters.
    orientation : int
        EXIF orientation 1..8 as :func:`prismcore.io.images.load_image` applies it (1 when missing
        or invalid); 5..8 mean the decoded image is the stored one turned by 90 degrees.
    pixel_width, pixel_height : int or None
        ``PixelXDimension`` x ``PixelYDimension``: the size of the image as the camera wrote it,
        in the stored (unrotated) frame.
    focal_35mm : float or None
        ``FocalLengthIn35mmFilm``, mm (0, "unknown" in EXIF, is None).
    focal_mm : float or None
        ``FocalLength``, mm: the lens's own focal length.
    focal_plane_x_res, focal_plane_y_res : float or None
        ``FocalPlaneXResolution`` / ``FocalPlaneYResolution``: image pixels (of the
        ``pixel_width`` wide image) per ``focal_plane_unit`` on the sensor, along the stored X and
        Y axes.
    focal_plane_unit : int
        ``FocalPlaneResolutionUnit`` as written: 2 inch (EXIF's default when absent), 3 cm;
        TIFF/EP's 4 mm and 5 micrometre are understood too, any other value makes the focal plane
        resolution unusable.
    """

    make: str | None = None
    model: str | None = None
    lens_model: str | None = None
    orientation: int = 1
    pixel_width: int | None = None
    pixel_height: int | None = None
    focal_35mm: float | None = None
    focal_mm: float | None = None
    focal_plane_x_res: float | None = None
    focal_plane_y_res: float | None = None
    focal_plane_unit: int = 2

    @property
    def turned(self) -> bool:
        """True when the decoded image is the stored one turned by 90 degrees (orientation 5..8)."""
        return self.orientation >= 5


@dataclass(frozen=True)
class ExifFocal:
    """A focal length derived from EXIF.

    Attributes
    ----------
    focal_px : float
        Focal length in pixels of the decoded image (square pixels).
    basis : str
        How it was derived, e.g. "FocalLengthIn35mmFilm 26 mm" or
        "FocalLength 4.25 mm at 7143 px/cm focal plane, resized 4032x3024 -> 1008x756 px".
    """

    focal_px: float
    basis: str


@dataclass(frozen=True)
class NoExifFocal:
    """Why no focal length could be derived from EXIF (a sentence a user can read)."""

    reason: str


# --------------------------------------------------------------------------------------------
# public API


def read_camera_exif(data: bytes | bytearray | memoryview) -> CameraExif | None:
    """Read the camera fields of a photo's EXIF data.

    Parameters
    ----------
    data : bytes
        The content of an image file that :func:`prismcore.io.images.load_image` reads (JPEG, PNG,
        WebP or TIFF), or a bare EXIF block starting with ``b"Exif\\0\\0"`` (an APP1 payload,
        as Pillow's ``im.info["exif"]`` holds it; its orientation is then read from the block).

    Returns
    -------
    CameraExif or None
        None when the data holds no EXIF block, or one Pillow cannot read at all, or is not an
        image ``load_image`` would accept; otherwise the fields found (any of them may be None).
        A broken block never raises: what cannot be read is missing.

    Raises
    ------
    InputError
        ``data`` is not bytes-like.

    Notes
    -----
    Pillow only *warns* on malformed blocks (a truncated directory, a tag's data past the
    end); its warnings are caught (``warnings.catch_warnings(record=True)``, which on Python
    < 3.14 swaps the process-wide filters for the duration of the read) and decide what is
    dropped: a cut directory whole, an out-of-range tag alone. Nothing is printed.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise InputError(f"EXIF source must be bytes, got {type(data).__name__}")
    data = bytes(data)
    if data.startswith(b"Exif\x00\x00"):
        block: bytes | None = data
        orientation: int | None = None
    else:
        try:
            info = probe_image(data)
        except InputError:
            return None
        block, orientation = _exif_block(data, info.format), info.orientation
    if not block:
        return None
    return _read_block(block, orientation)


def explain_exif_focal(
    exif: CameraExif, decoded_width: int, decoded_height: int
) -> ExifFocal | NoExifFocal:
    """Focal length in pixels of the decoded photo, or the reason there is none.

    Parameters
    ----------
    exif : CameraExif
        From :func:`read_camera_exif` for the same file.
    decoded_width, decoded_height : int
        Size in px of the image :func:`prismcore.io.images.load_image` returned for the file, which
        has the EXIF orientation applied: for orientation 5..8 the decoded width is the stored
        (and ``PixelYDimension``) height.

    Returns
    -------
    ExifFocal or NoExifFocal
        ``FocalLengthIn35mmFilm`` is used when present and plausible, else ``FocalLength`` with
        the focal plane resolution (see the module docstring for the formulas and the refusals).

    Raises
    ------
    InputError
        ``decoded_width`` or ``decoded_height`` is not a positive integer.
    """
    width, height = _positive_size(decoded_width, decoded_height)
    # The stored frame is the one PixelX/YDimension and FocalPlaneX/YResolution refer to.
    stored_w, stored_h = (height, width) if exif.turned else (width, height)
    diagonal = math.hypot(width, height)
    turn_note = f" (turned by EXIF orientation {exif.orientation})" if exif.turned else ""

    scale = None  # decoded px per original px, along the stored X axis
    size_note = ", original size not recorded (assumed as decoded)"
    if exif.pixel_width is not None and exif.pixel_height is not None:
        sx, sy = stored_w / exif.pixel_width, stored_h / exif.pixel_height
        if abs(sx / sy - 1.0) > _ASPECT_TOLERANCE + 1.0 / min(stored_w, stored_h):
            return NoExifFocal(
                f"the photo is {width}x{height} px{turn_note} but its EXIF says it was taken at "
                f"{exif.pixel_width}x{exif.pixel_height} px, a different aspect ratio (cropped?), "
                "so the EXIF focal length does not apply to it"
            )
        scale = sx
        size_note = (
            f", resized {exif.pixel_width}x{exif.pixel_height} -> {stored_w}x{stored_h} px"
            if (stored_w, stored_h) != (exif.pixel_width, exif.pixel_height)
            else ""
        )

    refused: list[str] = []
    if exif.focal_35mm is not None:
        f_px = exif.focal_35mm / FILM_35MM_DIAGONAL_MM * diagonal
        basis = f"FocalLengthIn35mmFilm {exif.focal_35mm:g} mm"
        if scale is None:
            basis += ", original size not recorded (assumed uncropped)"
        if _plausible(f_px, diagonal):
            return ExifFocal(f_px, basis)
        refused.append(_implausible(basis, f_px, diagonal))

    if exif.focal_mm is None or exif.focal_plane_x_res is None:
        if refused:
            return NoExifFocal(refused[0])
        named = (("FocalLength", exif.focal_mm), ("FocalPlaneXResolution", exif.focal_plane_x_res))
        lacking = [name for name, value in named if value is None]
        return NoExifFocal(f"the EXIF has no usable FocalLengthIn35mmFilm, nor {' or '.join(lacking)}")
    found = _focal_plane(exif, scale, diagonal, size_note + turn_note)
    if isinstance(found, NoExifFocal):
        return NoExifFocal("; ".join([*refused, found.reason]))
    if refused:  # say why the preferred value was passed over
        return ExifFocal(found.focal_px, f"{found.basis} ({refused[0]})")
    return found


def focal_px_from_exif(exif: CameraExif, decoded_width: int, decoded_height: int) -> ExifFocal | None:
    """:func:`explain_exif_focal` without the reason: the focal length, or None."""
    found = explain_exif_focal(exif, decoded_width, decoded_height)
    return found if isinstance(found, ExifFocal) else None


def camera_key(exif: CameraExif) -> str | None:
    """A name shared by the photos taken with one camera at one lens setting, for pooling.

    ``make|model|WxH`` (W x H the original size, stored frame, so upright and turned photos of
    one camera agree), followed by the lens model and the focal lengths when EXIF has them:
    a phone writes one make, model and size for its wide, ultra-wide and tele cameras, and a
    zoom lens changes the focal length between photos, so those must not share a focal length.

    Returns None when there is neither make nor model, or no original size: such photos are
    not known to share a camera.
    """
    if (exif.make is None and exif.model is None) or exif.pixel_width is None or exif.pixel_height is None:
        return None
    parts = [exif.make or "", exif.model or "", f"{exif.pixel_width}x{exif.pixel_height}"]
    if exif.lens_model is not None:
        parts.append(f"lens={exif.lens_model}")
    if exif.focal_mm is not None:
        parts.append(f"f={exif.focal_mm:g}mm")
    if exif.focal_35mm is not None:
        parts.append(f"f35={exif.focal_35mm:g}mm")
    return "|".join(p.replace("|", "/") for p in parts)


# --------------------------------------------------------------------------------------------
# the conversion


def _positive_size(width: object, height: object) -> tuple[int, int]:
    out = []
    for name, value in (("decoded_width", width), ("decoded_height", height)):
        try:
            if isinstance(value, bool):
                raise TypeError
            size = operator.index(value)  # type: ignore[arg-type]  # int or numpy integer; else TypeError
        except TypeError:
            size = 0
        if size < 1:
            raise InputError(f"{name} must be a positive integer (px), got {value!r}")
        out.append(size)
    return out[0], out[1]


def _plausible(f_px: float, diagonal: float) -> bool:
    lo, hi = _PLAUSIBLE_FOCAL_DIAGONALS
    return math.isfinite(f_px) and lo * diagonal <= f_px <= hi * diagonal


def _implausible(basis: str, f_px: float, diagonal: float) -> str:
    lo, hi = _PLAUSIBLE_FOCAL_DIAGONALS
    return (
        f"{basis} gives {f_px:.6g} px, outside the plausible {lo:g}..{hi:g} x the "
        f"{diagonal:.0f} px image diagonal"
    )


def _focal_plane(
    exif: CameraExif, scale: float | None, diagonal: float, note: str
) -> ExifFocal | NoExifFocal:
    """FocalLength times the focal plane resolution, scaled to the decoded pixels."""
    assert exif.focal_mm is not None and exif.focal_plane_x_res is not None
    unit = exif.focal_plane_unit
    if unit not in _MM_PER_UNIT:
        return NoExifFocal(f"FocalPlaneResolutionUnit {unit} is not a length unit (2 inch, 3 cm, 4 mm, 5 um)")
    res, res_y = exif.focal_plane_x_res, exif.focal_plane_y_res
    if res_y is not None and abs(res_y / res - 1.0) > _ASPECT_TOLERANCE:
        return NoExifFocal(
            f"FocalPlaneXResolution {res:g} and FocalPlaneYResolution {res_y:g} differ: "
            "non-square pixels (or a broken EXIF block)"
        )
    f_px = exif.focal_mm * res / _MM_PER_UNIT[unit] * (1.0 if scale is None else scale)
    basis = f"FocalLength {exif.focal_mm:g} mm at {res:.6g} px/{_UNIT_NAMES[unit]} focal plane{note}"
    if not _plausible(f_px, diagonal):
        return NoExifFocal(_implausible(basis, f_px, diagonal))
    return ExifFocal(f_px, basis)


# --------------------------------------------------------------------------------------------
# reading


def _read_block(block: bytes, orientation: int | None) -> CameraExif | None:
    """Fields from an EXIF block (TIFF structure, with or without the "Exif\\0\\0" prefix).

    A directory Pillow reports as cut short is dropped whole: the tags after the cut are lost
    without a trace, and a lost ``FocalPlaneResolutionUnit`` would silently default to inches.
    One tag whose data is out of range is only that tag lost (Pillow says "Skipping tag").
    """
    exif = Image.Exif()

    def load_ifd0() -> dict[int, Any]:
        exif.load(block)
        return dict(exif)

    ifd0 = _load_directory(load_ifd0)
    if not ifd0:
        return None
    sub: dict[int, Any] = {}
    if _EXIF_IFD in ifd0:
        sub = _load_directory(lambda: exif.get_ifd(_EXIF_IFD)) or {}
    # TIFF/EP puts FocalLength and the focal plane tags in IFD0.
    both = (sub, ifd0)

    if orientation is None:
        value = _integer(ifd0.get(_ORIENTATION))
        orientation = value if value is not None and 1 <= value <= 8 else 1
    width, height = _integer(sub.get(_PIXEL_X)), _integer(sub.get(_PIXEL_Y))
    unit = _integer(_first(both, _FP_UNIT, _EP_FP_UNIT))
    return CameraExif(
        make=_text(ifd0.get(_MAKE)),
        model=_text(ifd0.get(_MODEL)),
        lens_model=_text(sub.get(_LENS_MODEL)),
        orientation=orientation,
        pixel_width=width,
        pixel_height=height,
        focal_35mm=_number(sub.get(_FOCAL_35MM)),
        focal_mm=_number(_first(both, _FOCAL_LENGTH)),
        focal_plane_x_res=_number(_first(both, _FP_XRES, _EP_FP_XRES)),
        focal_plane_y_res=_number(_first(both, _FP_YRES, _EP_FP_YRES)),
        focal_plane_unit=2 if unit is None else unit,
    )


def _load_directory(load: Callable[[], Any]) -> dict[int, Any] | None:
    """What ``load`` reads of one EXIF directory; None if it fails or Pillow warns that the
    directory itself (not just one tag's data) is damaged."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            values = load()
    except _PIL_ERRORS:
        return None
    if any("Skipping tag" not in str(w.message) for w in caught):
        return None
    return values if isinstance(values, dict) else None


def _first(ifds: tuple[dict[int, Any], ...], *tags: int) -> Any:
    for ifd in ifds:
        for tag in tags:
            if ifd.get(tag) is not None:
                return ifd[tag]
    return None


def _scalar(value: Any) -> Any:
    # Pillow gives a tag with several values (malformed for these tags) as a tuple.
    if isinstance(value, (tuple, list)):
        return value[0] if value else None
    return value


def _number(value: Any) -> float | None:
    """A positive finite number (int, float or Pillow's IFDRational), else None."""
    value = _scalar(value)
    if value is None or isinstance(value, (bool, str, bytes)):
        return None
    try:
        number = float(value)  # IFDRational with a zero denominator gives nan
    except _PIL_ERRORS:
        return None
    return number if math.isfinite(number) and number > 0 else None


def _integer(value: Any) -> int | None:
    number = _number(value)
    return int(number) if number is not None and number == int(number) else None


_CONTROL = re.compile(r"[\x00-\x1f\x7f]+")


def _text(value: Any) -> str | None:
    if isinstance(value, bytes):  # an UNDEFINED-typed string
        value = value.decode("latin-1")
    if not isinstance(value, str):
        return None
    value = " ".join(_CONTROL.sub(" ", value).split())[:_MAX_TEXT]
    return value or None


def _exif_block(data: bytes, fmt: str) -> bytes | None:
    """The EXIF block of an image file of format ``fmt`` (as probe_image names it), or None.

    The same block :mod:`prismcore.io.images` takes the orientation from: the first "Exif" APP1
    segment of a JPEG before its first scan, a PNG's eXIf chunk before its image data, a WebP's
    EXIF chunk, and a TIFF file's own first directory.
    """
    if fmt == "TIFF":
        return data
    if fmt == "JPEG":
        return jpeg_header(data)[2]  # the segment walk the orientation is read by
    if fmt == "PNG":
        return _chunk(data, 8, ">I", b"eXIf", stop=(b"IDAT", b"IEND"), crc=True)
    if fmt == "WEBP":
        return _chunk(data, 12, "<I", b"EXIF", stop=(), crc=False)
    return None


def _chunk(
    data: bytes, pos: int, length_fmt: str, kind: bytes, *, stop: tuple[bytes, ...], crc: bool
) -> bytes | None:
    """Payload of the first ``kind`` chunk of a PNG (length, type, data, CRC) or RIFF (type,
    length, data, pad byte) chunk chain starting at ``pos``."""
    size = len(data)
    while pos + 8 <= size:
        if crc:  # PNG
            (length,) = struct.unpack_from(length_fmt, data, pos)
            name = data[pos + 4 : pos + 8]
        else:  # RIFF
            name = data[pos : pos + 4]
            (length,) = struct.unpack_from(length_fmt, data, pos + 4)
        if name == kind:
            return data[pos + 8 : pos + 8 + length]
        if name in stop:
            return None
        pos += 8 + length + (4 if crc else length & 1)
    return None


def exif_focal(data: bytes | bytearray | memoryview, decoded_width: int,
               decoded_height: int) -> ExifFocal | None:
    """The focal length, px of the decoded photo, that the photo's own EXIF gives; None when it
    has none that can be trusted (no EXIF, a crop, implausible values).

    data : the photo file's bytes, as given to `prismcore.io.images.load_image`.
    """
    exif = read_camera_exif(data)
    return None if exif is None else focal_px_from_exif(exif, decoded_width, decoded_height)

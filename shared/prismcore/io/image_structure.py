"""The structure of image files, read by this package itself before any decoder sees them: a
JPEG's segments (its size, its EXIF block), a PNG's chunk chain up to IEND, a WebP's RIFF header,
a TIFF's first directory with the EXIF and GPS directories it points to and its strip and tile
ranges, and the EXIF orientation. A damaged structure is refused (an InputError quoting the file),
where Pillow would only warn or accept a cut file; see `prismcore.io.images`.
"""

from __future__ import annotations

import mmap
import struct
from typing import Literal

import numpy as np
from PIL import TiffTags

from prismcore.errors import InputError

__all__ = ["jpeg_header"]


def _corrupt(label: str, fmt: str, reason: object) -> InputError:
    text = " ".join(str(reason).split())[:200] or type(reason).__name__
    return InputError(f"{label} is truncated or corrupt ({fmt}: {text})")

_ORIENTATION_TAG = 0x0112


def jpeg_header(buf: bytes | mmap.mmap) -> tuple[int, list[int], bytes | None]:
    """Walk a JPEG's marker segments up to the first scan.

    Returns the offset just past the start-of-scan segment (the whole header; the length of
    ``buf`` if no scan is found), the offsets of the "Exif" identifiers of the EXIF (APP1)
    segments, and the first EXIF payload.
    """
    size = len(buf)
    pos = 2
    idents: list[int] = []
    exif = None
    while pos + 4 <= size and buf[pos] == 0xFF:
        marker = buf[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:  # markers without a length
            pos += 2
            continue
        if marker == 0xD9:  # end of image before any scan
            break
        (length,) = struct.unpack(">H", bytes(buf[pos + 2 : pos + 4]))
        end = pos + 2 + length
        if marker == 0xDA:  # start of scan: the header ends with this segment
            return min(end, size), idents, exif
        if marker == 0xE1 and bytes(buf[pos + 4 : pos + 10]) == b"Exif\x00\x00":
            idents.append(pos + 4)
            if exif is None:
                exif = bytes(buf[pos + 4 : min(end, size)])
        pos = end
    return size, idents, exif


def _check_png_chunks(data: bytes, label: str) -> None:
    """The chunk chain must reach a complete IEND chunk (Pillow accepts a file cut within it,
    and the 16-bit path's libpng would then print an error)."""
    pos, size = 8, len(data)
    while pos + 12 <= size:
        (length,) = struct.unpack_from(">I", data, pos)
        kind = data[pos + 4 : pos + 8]
        pos += 12 + length
        if kind == b"IEND":
            if pos <= size:
                return
            break
    raise _corrupt(label, "PNG", "the file ends before its IEND chunk")


def _webp_header(buf: bytes | mmap.mmap, label: str) -> tuple[int, int, bool, bytes | None]:
    """(width, height, has_alpha, EXIF payload) from a WebP RIFF header, without decoding."""
    head = bytes(buf[:30])
    if len(head) < 30:
        raise _corrupt(label, "WEBP", f"{len(buf)}-byte file is shorter than a WebP header")
    (riff_size,) = struct.unpack_from("<I", head, 4)
    if riff_size + 8 > len(buf):
        raise _corrupt(label, "WEBP", f"header declares {riff_size + 8} bytes, file has {len(buf)}")
    kind = head[12:16]
    exif = None
    if kind == b"VP8 ":
        if head[23:26] != b"\x9d\x01\x2a":
            raise _corrupt(label, "WEBP", "bad VP8 start code")
        width, height = (v & 0x3FFF for v in struct.unpack_from("<HH", head, 26))
        alpha = False
    elif kind == b"VP8L":
        if head[20] != 0x2F:
            raise _corrupt(label, "WEBP", "bad VP8L signature")
        (bits,) = struct.unpack_from("<I", head, 21)
        width, height = (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
        alpha = bool((bits >> 28) & 1)
    elif kind == b"VP8X":
        flags = head[20]
        width = int.from_bytes(head[24:27], "little") + 1
        height = int.from_bytes(head[27:30], "little") + 1
        alpha = bool(flags & 0x10)
        if flags & 0x08:  # an EXIF chunk follows somewhere
            pos, end = 12, min(len(buf), riff_size + 8)
            while pos + 8 <= end:
                fourcc = bytes(buf[pos : pos + 4])
                (size,) = struct.unpack("<I", bytes(buf[pos + 4 : pos + 8]))
                if fourcc == b"EXIF":
                    exif = bytes(buf[pos + 8 : pos + 8 + size])
                    break
                pos += 8 + size + (size & 1)
    else:
        raise _corrupt(label, "WEBP", f"unknown WebP chunk {kind!r}")
    if width == 0 or height == 0:
        raise _corrupt(label, "WEBP", f"header declares a {width}x{height} image")
    return width, height, alpha, exif


class _CorruptError(Exception):
    """A TIFF structure that points outside its data."""


# TIFF field type -> bytes per value; integer types -> numpy type code.
_TIFF_SIZES = {
    1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4, 16: 8, 17: 8, 18: 8
}  # fmt: skip
_TIFF_INTS = {1: "u1", 3: "u2", 4: "u4", 6: "i1", 8: "i2", 9: "i4", 13: "u4", 16: "u8", 17: "i8", 18: "u8"}
# width, height, bits per sample, strip offsets, orientation, strip byte counts, tile offsets,
# tile byte counts, and the pointers to the EXIF, GPS and interoperability directories
_TIFF_WANTED = frozenset({256, 257, 258, 273, 274, 279, 324, 325, 34665, 34853, 40965})
_SUB_IFD_TAGS = (34665, 34853, 40965)
_MAX_TIFF_ENTRIES = 4096  # real directories hold a few dozen; more is a crafted file


def _tiff_ifd0(
    buf: bytes | mmap.mmap, wanted: frozenset[int], *, strict: bool = True
) -> dict[int, np.ndarray]:
    """Integer values of the ``wanted`` tags of the first directory (IFD) of a TIFF structure.

    ``strict`` (for TIFF files): any tag's data outside ``buf`` raises _CorruptError, and the
    directories the EXIF, GPS and interoperability pointers lead to are checked the same way
    (Pillow reads them while loading a TIFF, and only warns if they are cut off). Otherwise (for
    EXIF blocks) such tags are skipped. A header or first directory outside ``buf`` always
    raises. Handles classic TIFF and BigTIFF, either byte order.
    """
    head = bytes(buf[:16])
    if len(head) < 8 or head[:2] not in (b"II", b"MM"):
        raise _CorruptError("no TIFF header")
    bo: Literal["<", ">"] = "<" if head[:2] == b"II" else ">"
    (magic,) = struct.unpack_from(bo + "H", head, 2)
    if magic == 42:
        (ifd,) = struct.unpack_from(bo + "I", head, 4)
        big = False
    elif magic == 43 and len(head) == 16:
        (ifd,) = struct.unpack_from(bo + "Q", head, 8)
        big = True
    else:
        raise _CorruptError(f"bad TIFF header {head[:8]!r}")
    tags = _tiff_ifd(buf, ifd, bo, big, wanted | frozenset(_SUB_IFD_TAGS), strict, None)
    for pointer in _SUB_IFD_TAGS if strict else ():
        if pointer in tags and tags[pointer].size:
            sub = _tiff_ifd(buf, int(tags[pointer][0]), bo, big, frozenset({40965}), strict, pointer)
            if 40965 in sub and sub[40965].size:  # interoperability directory, inside EXIF's
                _tiff_ifd(buf, int(sub[40965][0]), bo, big, frozenset(), strict, 40965)
    return {tag: values for tag, values in tags.items() if tag in wanted}


def _tiff_ifd(
    buf: bytes | mmap.mmap,
    ifd: int,
    bo: Literal["<", ">"],
    big: bool,
    wanted: frozenset[int],
    strict: bool,
    group: int | None,
) -> dict[int, np.ndarray]:
    """Integer values of the ``wanted`` tags of the directory at byte ``ifd``.

    ``group`` is the pointer tag that led here (None for the first directory); in ``strict``
    mode a tag the TIFF/EXIF specifications give a single value must have one value (Pillow
    warns and drops the rest otherwise).
    """
    size = len(buf)
    if big:
        count_fmt, entry_fmt, entry_size, inline, offset_fmt = "Q", "HHQ8s", 20, 8, "Q"
    else:
        count_fmt, entry_fmt, entry_size, inline, offset_fmt = "H", "HHI4s", 12, 4, "I"
    count_size = struct.calcsize(count_fmt)
    if ifd < 8 or ifd + count_size > size:
        raise _CorruptError(f"directory at byte {ifd} is outside the {size}-byte data")
    (n,) = struct.unpack(bo + count_fmt, bytes(buf[ifd : ifd + count_size]))
    start = ifd + count_size
    if n == 0 or n > _MAX_TIFF_ENTRIES or start + n * entry_size > size:
        raise _CorruptError(f"directory of {n} entries at byte {ifd} does not fit in {size} bytes")
    table = bytes(buf[start : start + n * entry_size])
    tags: dict[int, np.ndarray] = {}
    total = 0
    for tag, typ, count, raw in struct.iter_unpack(bo + entry_fmt, table):
        unit = _TIFF_SIZES.get(typ)
        if unit is None:
            continue  # unknown field types are skipped, as TIFF readers do
        if strict and count != 1 and typ not in (1, 2, 7) and TiffTags.lookup(tag, group).length == 1:
            raise _CorruptError(f"tag {tag} has {count} values, expected 1")
        nbytes = count * unit
        if nbytes <= inline:
            data = raw[:nbytes]
        else:
            (offset,) = struct.unpack(bo + offset_fmt, raw)
            total += nbytes
            if offset > size or nbytes > size - offset or total > size:
                if not strict:
                    continue
                raise _CorruptError(
                    f"tag {tag} data at bytes {offset}..{offset + nbytes} is past the end ({size})"
                )
            data = bytes(buf[offset : offset + nbytes]) if tag in wanted else b""
        if tag in wanted and typ in _TIFF_INTS:
            tags[tag] = np.frombuffer(data, dtype=np.dtype(_TIFF_INTS[typ]).newbyteorder(bo))
    return tags


def _check_tiff_ranges(tags: dict[int, np.ndarray], size: int, label: str) -> None:
    """Every strip or tile of the first image must lie inside the file."""
    for offsets_tag, counts_tag in ((273, 279), (324, 325)):
        if offsets_tag not in tags or counts_tag not in tags:
            continue
        offsets = tags[offsets_tag].astype(np.uint64)
        counts = tags[counts_tag].astype(np.uint64)
        if offsets.shape != counts.shape:
            raise _corrupt(label, "TIFF", f"{offsets.size} data offsets but {counts.size} byte counts")
        end = np.uint64(size)
        outside = (offsets > end) | (counts > end - np.minimum(offsets, end))
        if outside.any():
            i = int(np.argmax(outside))
            raise _corrupt(
                label,
                "TIFF",
                f"image data at bytes {int(offsets[i])}..{int(offsets[i]) + int(counts[i])} "
                f"is past the end of the {size}-byte file",
            )


def _valid_orientation(value: int) -> int:
    return value if 1 <= value <= 8 else 1


def _exif_orientation(exif: bytes | None) -> int:
    """EXIF Orientation (1..8) from an EXIF block (with or without the "Exif\\0\\0" prefix);
    1 when absent or unreadable, as browsers treat a broken EXIF block."""
    if not exif:
        return 1
    if exif.startswith(b"Exif\x00\x00"):
        exif = exif[6:]
    try:
        values = _tiff_ifd0(exif, frozenset({_ORIENTATION_TAG}), strict=False).get(_ORIENTATION_TAG)
    except (_CorruptError, struct.error, ValueError):
        return 1
    return _valid_orientation(int(values[0])) if values is not None and values.size else 1

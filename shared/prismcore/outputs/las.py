"""LAS 1.2 and LAZ (compressed LAS) point clouds with RGB, for survey, GIS and CloudCompare.

Units and axes: LAS tools assume metres and Z up, so the box frame (mm; X along P1 -> P2, Y down
the front face, Z into the object) is written as

    X = x / 1000,   Y = z / 1000,   Z = -y / 1000      (metres; a rotation of +90 degrees about X)

i.e. P1 at the origin, the box's top face at Z = 0 and its body below it, the front face in the
plane Y = 0 and the depth along +Y. Coordinates are stored as integers with a scale of
:data:`SCALE_M` = 0.0001 m (0.1 mm, far below any measurement's uncertainty; the float32
cloud itself carries about 0.01 mm at a metre) and offset 0: an int32 reaches +-214 km.

Points use point data format 2 (X, Y, Z, intensity, return fields, classification, ..., red,
green, blue); colours are the 8-bit RGB scaled to LAS's 16 bits by 257 (255 -> 65535, so
``value // 257`` gives the 8-bit colour back). LAZ is compressed by lazrs (Rust, through
laspy's ``LazBackend.Lazrs``), which needs a seekable destination (a path, a file opened
'wb', ``io.BytesIO``, a spooled temporary file).
"""

from __future__ import annotations

import os
from typing import BinaryIO

import numpy as np

from prismcore.errors import InputError
from prismcore.outputs.cloud_check import check_cloud

__all__ = ["COLOR_SCALE", "SCALE_M", "box_to_las", "write_las"]

SCALE_M = 1e-4
"""LAS coordinate resolution, metres (0.1 mm)."""

COLOR_SCALE = 257
"""8-bit colour -> LAS 16-bit colour factor."""

_CHUNK = 1 << 20  # points per block written: bounded memory however large the cloud


def box_to_las(points: np.ndarray) -> np.ndarray:
    """Box-frame points (N, 3) mm -> LAS (N, 3) float64 metres: (x, z, -y) / 1000."""
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1) / 1000.0


def write_las(dest: str | os.PathLike[str] | BinaryIO, points: np.ndarray, colors: np.ndarray | None = None,
              *, compressed: bool = True) -> int:
    """Write the cloud as LAZ (``compressed=True``) or LAS; return the number of bytes written.

    Parameters
    ----------
    dest : path or seekable binary file object
        A path is created or truncated; a file object is written from its current position and
        left open.
    points : ndarray, shape (N, 3), float32 or float64
        Box frame, mm (see the module's axis mapping).
    colors : ndarray, shape (N, 3), uint8, optional
        RGB; without them the colour fields are 0.
    compressed : bool
        LAZ (lazrs) instead of plain LAS.

    Raises
    ------
    InputError
        Bad points or colours (as the other writers), a non-seekable destination, or a
        coordinate beyond the int32 range at 0.1 mm.
    """
    import laspy  # here: the other writers do not need it


    points, colors = check_cloud(points, colors)
    if len(points):
        biggest = max(float(np.abs(points.min())), float(np.abs(points.max())))
        if biggest / 1000.0 / SCALE_M >= 2**31 - 1:
            raise InputError(f"points hold {biggest!r} mm, beyond LAS's int32 range at 0.1 mm")
    header = laspy.LasHeader(point_format=2, version="1.2")
    header.scales = np.array([SCALE_M] * 3)
    header.offsets = np.zeros(3)
    header.generating_software = "PrismCloud"
    header.system_identifier = "PrismCloud box scan"

    def write(fh: BinaryIO) -> int:
        if not (hasattr(fh, "seekable") and fh.seekable()):
            raise InputError("LAS/LAZ needs a seekable destination (a path or a seekable file object)")
        start = fh.tell()
        backend = laspy.LazBackend.Lazrs if compressed else None
        with laspy.open(fh, mode="w", header=header, do_compress=compressed, laz_backend=backend,
                        closefd=False) as writer:
            for lo in range(0, len(points), _CHUNK):
                block = np.asarray(points[lo:lo + _CHUNK], dtype=np.float64)
                record = laspy.ScaleAwarePointRecord.zeros(len(block), header=header)
                # Straight into the record's array, a column at a time: box_to_las's arithmetic
                # (the same values, bit for bit) without its (N, 3) copies or laspy's
                # per-field assignment, half the record's cost.
                fields = record.array
                for name, axis, sign in (("X", 0, 1.0), ("Y", 2, 1.0), ("Z", 1, -1.0)):
                    fields[name] = np.rint(sign * block[:, axis] / 1000.0 / SCALE_M)
                if colors is not None:
                    for name, channel in (("red", 0), ("green", 1), ("blue", 2)):
                        fields[name] = colors[lo:lo + _CHUNK, channel].astype(np.uint16) * COLOR_SCALE
                writer.write_points(record)
        fh.seek(0, os.SEEK_END)
        return fh.tell() - start

    if isinstance(dest, str | os.PathLike):
        with open(dest, "wb") as fh:
            return write(fh)
    if not callable(getattr(dest, "write", None)):
        raise InputError(f"dest must be a path or a binary file object, got {type(dest).__name__}")
    return write(dest)

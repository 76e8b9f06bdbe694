"""Fast point-cloud writers: comma-separated X,Y,Z text and PLY.

Both writers take ``points`` (N, 3) float32/float64 and optional ``colors`` (N, 3) uint8, write
to a path or to an open *binary* file object (anything with ``write(bytes)``: a file opened
'wb', ``io.BytesIO``, an object-storage upload stream), and return the number of bytes written.

They work in blocks of :data:`CHUNK_ROWS` rows, so memory beyond the caller's arrays stays at a
few tens of megabytes whatever the cloud's size, and nothing loops over points in Python:

* CSV text is formatted by polars (Rust). Each coordinate is cast to a polars ``Decimal`` with
  ``decimals`` digits after the point, which prints fixed notation, never an exponent and never
  ``-0.000``; the result is the correctly rounded decimal value (ties to even), exactly what
  ``'%.3f' % x`` gives, except that a negative value which rounds to zero prints ``0.000``.
* Binary PLY is a packed numpy structured array written straight from its buffer.
* ASCII PLY bodies are formatted by polars too, as the shortest text that reads back to the same
  float32, so ASCII files round-trip exactly like binary ones.

Inputs are validated before any byte is written (a path is not even opened on bad input) and
never modified.
"""

from __future__ import annotations

import io
import json
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np
import polars as pl

from prismcore.errors import InputError
from prismcore.formats import FILE_NAMES, PART_FORMATS, output_files
from prismcore.outputs.cloud_check import check_cloud
from prismcore.report import ScanReport, report_dict

if TYPE_CHECKING:
    from prismcore.scan.cloud import Cloud
    from prismcore.spec import ScanSpec

__all__ = ["CHUNK_ROWS", "DEFAULT_OVERLAY_FORMAT", "FILE_NAMES", "MAX_DECIMALS", "OVERLAY_FORMATS",
           "PART_FILES", "encode_overlay", "encode_png", "overlay_name", "write_csv", "write_format",
           "write_part", "write_ply"]

CHUNK_ROWS = 1 << 17
"""Rows formatted per block: about 3.5 MB of CSV text at 3 decimals."""

MAX_DECIMALS = 17
"""More digits than a float64 carries would only print noise."""

# Beyond this |x * 10**decimals| the Decimal route is not guaranteed exact (see _csv_block);
# such blocks (|x| >= ~1e12 at 3 decimals) are printed by polars' float formatter instead.
_DECIMAL_LIMIT = 2.0**50
# float64 magnitudes from here on round to inf when cast to float32 (2**128 - 2**103 is the
# midpoint between FLT_MAX and 2**128, and ties go to even, i.e. to inf).
_F32_OVERFLOW = 2.0**128 - 2.0**103
_PLY_DTYPE_XYZ = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
_PLY_DTYPE_XYZRGB = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
)

Dest = str | os.PathLike[str] | BinaryIO


# --------------------------------------------------------------------------------------------
# public API


def write_csv(
    dest: Dest,
    points: np.ndarray,
    colors: np.ndarray | None = None,
    *,
    header: bool = False,
    decimals: int = 3,
) -> int:
    """Write one ``x,y,z`` text row per point; return the number of bytes written.

    The default (no header, no colours) is exactly the paper's comma-separated X,Y,Z text,
    which CAD point-cloud importers read directly, so that is what a bare call produces.

    Parameters
    ----------
    dest : path or binary file object
        A path is created or truncated; a file object is written at its current position and
        left open. Text-mode file objects are refused.
    points : ndarray, shape (N, 3), float32 or float64
        Finite x, y, z.
    colors : ndarray, shape (N, 3), uint8, optional
        When given, ``,r,g,b`` is appended to each row.
    header : bool
        Start with the line ``x,y,z`` (``x,y,z,r,g,b`` with colours).
    decimals : int
        Digits after the decimal point, always all printed (``12.500``), 0 to 17. Values are
        rounded correctly (ties to even) from the exact binary value, never in exponent
        notation, and ``-0.000`` is written ``0.000``.

    Lines end with ``\\n``. An empty cloud gives an empty file (just the header line, if asked).

    Raises
    ------
    InputError
        Bad shape, dtype, row count, non-finite value, ``decimals`` or ``dest``.
    """
    points, colors = check_cloud(points, colors)
    if isinstance(decimals, bool) or not isinstance(decimals, int | np.integer):
        raise InputError(f"decimals must be an integer, got {decimals!r}")
    decimals = int(decimals)
    if not 0 <= decimals <= MAX_DECIMALS:
        raise InputError(f"decimals must be between 0 and {MAX_DECIMALS}, got {decimals}")
    head = b""
    if header:
        head = b"x,y,z,r,g,b\n" if colors is not None else b"x,y,z\n"

    def blocks() -> Iterator[bytes | memoryview]:
        if head:
            yield head
        for start in range(0, len(points), CHUNK_ROWS):
            stop = start + CHUNK_ROWS
            cols = None if colors is None else colors[start:stop]
            yield _csv_block(points[start:stop], cols, decimals)

    return _emit(dest, blocks())


def write_ply(
    dest: Dest,
    points: np.ndarray,
    colors: np.ndarray | None = None,
    *,
    ascii: bool = False,
    comment: str | None = None,
) -> int:
    """Write a PLY 1.0 file with one ``vertex`` element; return the number of bytes written.

    Vertex properties are ``float x, y, z`` and, when colours are given,
    ``uchar red, green, blue``. The body is ``binary_little_endian`` by default; with
    ``ascii=True`` it is one space-separated line per vertex, each coordinate written as the
    shortest text that reads back as the same float32 (so it may use exponent notation, which
    every PLY reader accepts). float64 points are stored as float32 (rounded to nearest).

    Parameters
    ----------
    dest : path or binary file object
        As for :func:`write_csv`. As with any ``io`` stream, ``write(b)`` must copy what it
        keeps of ``b`` before returning: the binary body reuses one block buffer.
    points : ndarray, shape (N, 3), float32 or float64
    colors : ndarray, shape (N, 3), uint8, optional
    ascii : bool
        Text body instead of binary.
    comment : str, optional
        One ``comment`` line in the header: printable ASCII, no line breaks.

    Raises
    ------
    InputError
        Bad shape, dtype, row count, non-finite value (or a float64 value too large for
        float32), bad ``comment`` or ``dest``.
    """
    points, colors = check_cloud(points, colors)
    if points.dtype == np.float64 and len(points):
        biggest = max(float(points.max()), -float(points.min()))
        if biggest >= _F32_OVERFLOW:
            raise InputError(f"points hold {biggest!r}, too large for the PLY float type")
    head = _ply_header(len(points), colors is not None, ascii, comment)

    def blocks() -> Iterator[bytes | memoryview]:
        yield head
        if ascii:
            for start in range(0, len(points), CHUNK_ROWS):
                stop = start + CHUNK_ROWS
                cols = None if colors is None else colors[start:stop]
                yield _ply_ascii_block(points[start:stop], cols)
            return
        dtype = _PLY_DTYPE_XYZ if colors is None else _PLY_DTYPE_XYZRGB
        buf = np.empty(min(len(points), CHUNK_ROWS), dtype=dtype)
        for start in range(0, len(points), CHUNK_ROWS):
            block = points[start:start + CHUNK_ROWS]
            rec = buf[: len(block)]
            rec["x"], rec["y"], rec["z"] = block[:, 0], block[:, 1], block[:, 2]
            if colors is not None:
                rgb = colors[start:start + CHUNK_ROWS]
                rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
            # _write_blocks has handed a block to write() before the generator resumes, and
            # write() may not keep a buffer after it returns, so the one buffer is refilled.
            yield rec.view(np.uint8).data

    return _emit(dest, blocks())


# --------------------------------------------------------------------------------------------
# validation


def write_format(kind: str, dest: str | os.PathLike[str] | BinaryIO, cloud: Cloud, spec: ScanSpec, *,
                 report: ScanReport | Mapping[str, Any] | None = None,
                 images: Sequence[np.ndarray] | None = None, when: datetime | None = None) -> float:
    """Write `kind` (one of `prismcore.spec.FORMATS`, or of the files a format writes:
    `prismcore.spec.output_files`) with the spec's options; returns the ms taken.

    The one place that maps a spec's output options (CSV header and colours, ASCII PLY) onto
    the writers, for the CLI and the service alike. "csv", "ply", "las" and "laz" write the
    cloud (LAS/LAZ: see `prismcore.outputs.las` for its metres and axes; they need a seekable `dest`);
    "glb" writes the fitted box textured from the photos (`prismcore.outputs.glb`) and needs
    `report` (the scan's report; a report.json dict is read as `ScanReport`) and `images` (the
    front photo, and the side photo in two-photo mode, as decoded). The part's CAD files need
    `report` too and are dated `when` (now, UTC, if not given): "step" the STEP solid and
    "step_meta" its JSON sidecar (`prismcore.outputs.step`), "drawing_svg", "drawing_pdf" and
    "drawing_dxf" the inspection sheet (`prismcore.outputs.drawing`); a report without a scale (in
    px) is refused.
    """
    start = time.perf_counter()
    if kind == "csv":
        write_csv(dest, cloud.points, cloud.colors if spec.csv.colors else None,
                  header=spec.csv.header)
    elif kind == "ply":
        write_ply(dest, cloud.points, cloud.colors, ascii=spec.ply_ascii)
    elif kind in ("las", "laz"):
        from prismcore.outputs.las import write_las

        write_las(dest, cloud.points, cloud.colors, compressed=kind == "laz")
    elif kind == "glb":
        if report is None or not images:
            raise InputError("the glb model needs the scan's report and its photos")
        from prismcore.outputs.glb import box_glb

        typed = report if isinstance(report, ScanReport) else ScanReport.model_validate(report)
        data = box_glb(typed, images[0], images[1] if len(images) > 1 else None)
        _emit(dest, iter([data]))
    elif kind in PART_FILES:
        if report is None:
            raise InputError(f"the {kind} file needs the scan's report")
        write_part(kind, dest, report_dict(report) if isinstance(report, ScanReport) else report, when)
    else:
        raise InputError(f"unknown output format {kind!r}")
    return (time.perf_counter() - start) * 1000


PART_FILES = tuple(output_files(PART_FORMATS))
"""The part's CAD files (the format table's part formats: step and drawing): written from a report
alone, so a joint fit, which makes no cloud, has them too."""


def write_part(kind: str, dest: Dest, report: Mapping[str, Any], when: datetime | None = None) -> float:
    """Write one of the part's CAD files (`PART_FILES`) of the measurement `report` (a scan's
    report.json, or a joint fit's joint.json with its quality and scale), dated `when` (now, UTC,
    by default); returns the ms taken.

    Raises
    ------
    InputError
        An unknown kind, a report without a scale (in px), OCP missing for step.
    """
    start = time.perf_counter()
    if kind not in PART_FILES:
        raise InputError(f"unknown part file {kind!r}: expected one of {', '.join(PART_FILES)}")
    _emit(dest, iter([_cad_file(kind, report, when or datetime.now(UTC))]))
    return (time.perf_counter() - start) * 1000


def _cad_file(kind: str, report: Mapping[str, Any], when: datetime) -> bytes:
    """The bytes of one of the part's CAD files (`_CAD_FILES`)."""
    from prismcore.outputs.part import part_from_report

    part = part_from_report(report, "the step format" if kind.startswith("step")
                            else "the stl format" if kind == "stl" else "the drawing")
    if kind == "stl":
        from prismcore.outputs.stl import box_stl

        return box_stl(part)
    if kind == "step":
        from prismcore.outputs.step import step_bytes

        return step_bytes(part, when)
    if kind == "step_meta":
        from prismcore.outputs.step import step_metadata

        return (json.dumps(step_metadata(part), indent=2) + "\n").encode()
    from prismcore.outputs import drawing_files

    writer = {"drawing_svg": drawing_files.drawing_svg, "drawing_pdf": drawing_files.drawing_pdf,
              "drawing_dxf": drawing_files.drawing_dxf}[kind]
    return writer(part, when)


def _ply_header(n: int, with_colors: bool, ascii: bool, comment: str | None) -> bytes:
    lines = ["ply", f"format {'ascii' if ascii else 'binary_little_endian'} 1.0"]
    if comment is not None:
        if not isinstance(comment, str):
            raise InputError(f"comment must be a string, got {type(comment).__name__}")
        if not all(" " <= ch <= "~" for ch in comment):
            raise InputError(f"comment must be printable ASCII on one line, got {comment!r}")
        lines.append(f"comment {comment}".rstrip())
    lines += [f"element vertex {n}", "property float x", "property float y", "property float z"]
    if with_colors:
        lines += ["property uchar red", "property uchar green", "property uchar blue"]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


# --------------------------------------------------------------------------------------------
# block formatting


def _csv_block(block: np.ndarray, colors: np.ndarray | None, decimals: int) -> memoryview:
    """Format one block of rows as CSV text.

    Route: polars casts float64 -> Decimal(38, d) as rint(fl(x * 10**d)) (ties to even) and
    prints the integer with the point inserted. That is the correctly rounded result whenever
    the float product x * 10**d is exact, which it is for float32 input with d <= 12 (24 + 28
    significant bits fit in float64). Otherwise rint(fl(T)) can differ from round(T) only when
    fl(T) lands exactly on a half-integer that T itself is not (rounding is monotonic and the
    half-integers are representable below 2**52): those rows are found, their true side taken
    from the exact product error (Dekker's two-product), and their value replaced by one whose
    product lands next to the right integer.
    """
    scale = 10.0**decimals
    x = np.array(block.T, dtype=np.float64, order="C")  # (3, n): a contiguous row per axis
    if len(block) and max(float(x.max()), -float(x.min())) * scale >= _DECIMAL_LIMIT:
        return _csv_block_float(x, colors, decimals)
    if block.dtype != np.float32 or decimals > 12:
        _fix_float64_ties(x, scale)
    dec = pl.Decimal(38, decimals)
    frame = pl.DataFrame(
        {name: pl.Series(name, col).cast(dec) for name, col in zip("xyz", x, strict=True)}
    )
    if colors is not None:
        frame = frame.hstack(_color_series(colors))
    return _frame_to_csv(frame, ",")


def _csv_block_float(x: np.ndarray, colors: np.ndarray | None, decimals: int) -> memoryview:
    """Huge values: polars' own fixed-point float formatter (exact, but prints -0.000)."""
    x[_rounds_to_negative_zero(x, decimals)] = 0.0
    frame = pl.DataFrame({name: col for name, col in zip("xyz", x, strict=True)})
    if colors is not None:
        frame = frame.hstack(_color_series(colors))
    return _frame_to_csv(frame, ",", float_precision=decimals)


def _fix_float64_ties(x: np.ndarray, scale: float) -> None:
    """In place: make rint(fl(x * scale)) the correctly rounded x * scale (see _csv_block)."""
    prod = x * scale
    frac = prod - np.floor(prod)
    rows = np.nonzero(frac == 0.5)
    if not rows[0].size:
        return
    a, p = x[rows], prod[rows]
    err = _two_product_error(a, scale, p)  # a * scale == p + err exactly
    target = np.where(err > 0, p + 0.5, np.where(err < 0, p - 0.5, p))
    exact_tie = err == 0  # a true tie: rint's ties-to-even is already right
    x[rows] = np.where(exact_tie, a, target / scale)


def _two_product_error(a: np.ndarray, b: float, p: np.ndarray) -> np.ndarray:
    """Dekker: the exact a * b - p for p = fl(a * b), without FMA (no overflow here)."""
    split = 134217729.0  # 2**27 + 1
    t = a * split
    a_hi = t - (t - a)
    a_lo = a - a_hi
    tb = b * split
    b_hi = tb - (tb - b)
    b_lo = b - b_hi
    error: np.ndarray = ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo
    return error


def _rounds_to_negative_zero(x: np.ndarray, decimals: int) -> np.ndarray:
    """Where '%.{decimals}f' would print a signed zero, '-0.000'."""
    half = 5 / 10 ** (decimals + 1)  # int / int: the double nearest the true half unit
    # Does the double `half` itself print as zero? Compare it with the true 5 * 10**-(d+1).
    num, den = half.as_integer_ratio()
    half_prints_zero = num * 10 ** (decimals + 1) <= 5 * den  # at or below: tie-to-even or less
    inside = (x >= -half) if half_prints_zero else (x > -half)
    negative_zero: np.ndarray = np.signbit(x) & inside
    return negative_zero


def _ply_ascii_block(block: np.ndarray, colors: np.ndarray | None) -> memoryview:
    x = np.array(block.T, dtype=np.float32, order="C")
    x += np.float32(0.0)  # -0.0 + 0.0 == +0.0: no "-0.0" in the text
    frame = pl.DataFrame({name: col for name, col in zip("xyz", x, strict=True)})
    if colors is not None:
        frame = frame.hstack(_color_series(colors))
    return _frame_to_csv(frame, " ")


def _color_series(colors: np.ndarray) -> list[pl.Series]:
    return [pl.Series(name, np.ascontiguousarray(colors[:, i])) for i, name in enumerate("rgb")]


def _frame_to_csv(frame: pl.DataFrame, separator: str, **options: Any) -> memoryview:
    out = io.BytesIO()
    frame.write_csv(out, include_header=False, separator=separator, line_terminator="\n",
                    quote_style="never", **options)
    return out.getbuffer()


# --------------------------------------------------------------------------------------------
# output


def _emit(dest: Dest, blocks: Iterator[bytes | memoryview]) -> int:
    """Write every block to dest (a path, or a binary file object); return the byte count."""
    if isinstance(dest, str | os.PathLike):
        with open(dest, "wb") as fh:
            return _write_blocks(fh.write, blocks)
    if isinstance(dest, io.TextIOBase):
        raise InputError(f"dest must be a path or a binary file object, got text stream {dest!r}")
    write = getattr(dest, "write", None)
    if not callable(write):
        raise InputError(
            f"dest must be a path or a binary file object, got {type(dest).__name__}"
        )
    return _write_blocks(write, blocks)


def _write_blocks(write: Callable[[Any], Any], blocks: Iterator[bytes | memoryview]) -> int:
    total = 0
    for block in blocks:
        view = memoryview(block)
        size = view.nbytes
        done = 0
        while done < size:  # raw (unbuffered) streams may take less than offered
            n = write(view[done:])
            if n is None:  # file-likes that return nothing took it all
                break
            if n <= 0:
                raise OSError(f"write to {write!r} made no progress")
            done += n
        total += size
        view.release()
    return total


def encode_png(rgb: np.ndarray) -> bytes:
    """PNG bytes of a picture (an overlay of the fit, say).

    rgb : (H, W, 3) uint8 RGB. OpenCV encodes BGR, hence the swap.
    """
    import cv2  # here: writing clouds needs no OpenCV

    ok, data = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise InputError(f"could not encode a {rgb.shape[1]}x{rgb.shape[0]} picture as PNG")
    return data.tobytes()


OVERLAY_FORMATS = {"jpeg": ".jpg", "png": ".png", "webp": ".webp"}
"""The overlay's picture formats and their file suffixes."""
DEFAULT_OVERLAY_FORMAT = "jpeg"
"""A picture a person looks at: JPEG (quality 90, colour kept at full resolution so the thin
coloured lines stay sharp) is encoded in ~5 ms and ~0.25 MB for a 1280x1024 overlay, where PNG
took ~40 ms and 1.4 MB; PNG (lossless) on request."""
_JPEG_QUALITY = 90


def overlay_name(kind: str = "overlay", fmt: str = DEFAULT_OVERLAY_FORMAT) -> str:
    """The overlay's file name in `fmt`: FILE_NAMES' (overlay.png, overlay_side.png) with the
    format's suffix (overlay.jpg by default)."""
    if fmt not in OVERLAY_FORMATS:
        raise InputError(f"overlay format {fmt!r}: expected one of {', '.join(OVERLAY_FORMATS)}")
    return os.path.splitext(FILE_NAMES[kind])[0] + OVERLAY_FORMATS[fmt]


def encode_overlay(rgb: np.ndarray, fmt: str = DEFAULT_OVERLAY_FORMAT) -> bytes:
    """The overlay picture's bytes in `fmt` (jpeg, png or webp).

    rgb : (H, W, 3) uint8 RGB.
    """
    if fmt == "png":
        return encode_png(rgb)
    if fmt not in OVERLAY_FORMATS:
        raise InputError(f"overlay format {fmt!r}: expected one of {', '.join(OVERLAY_FORMATS)}")
    import cv2  # here: writing clouds needs no OpenCV

    if fmt == "jpeg":
        params = [cv2.IMWRITE_JPEG_QUALITY, _JPEG_QUALITY, cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                  cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    else:
        params = [cv2.IMWRITE_WEBP_QUALITY, _JPEG_QUALITY]
    ok, data = cv2.imencode(OVERLAY_FORMATS[fmt], cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise InputError(f"could not encode a {rgb.shape[1]}x{rgb.shape[0]} picture as {fmt}")
    return bytes(data.tobytes())

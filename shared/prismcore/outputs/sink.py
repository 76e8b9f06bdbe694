"""A scan's files written into a sink: the one output writing the CLI and the worker share.

The engine does no I/O of its own here: it hands each file to the caller's `Sink` as bytes, or as
a function that writes it into a binary file object the sink provides. The CLI's sink is a folder,
the worker's the object store; both get the same files, named and typed by `prismcore.formats`.
"""

from __future__ import annotations

import json
import mimetypes
import time
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime
from functools import partial
from typing import TYPE_CHECKING, Any, BinaryIO, Protocol

import numpy as np

from prismcore.formats import FILE_NAMES, media_type, output_files
from prismcore.outputs.overlay_report import overlay_from_report
from prismcore.outputs.writers import (
    DEFAULT_OVERLAY_FORMAT,
    encode_overlay,
    overlay_name,
    write_format,
    write_part,
)
from prismcore.report import ScanReport, report_dict

if TYPE_CHECKING:
    from prismcore.scan.pipeline import ScanResult
    from prismcore.spec import ScanSpec

__all__ = ["Sink", "Writer", "overlay_media_type", "report_bytes", "write_outputs", "write_part_files"]

Writer = Callable[[BinaryIO], object]
"""Writes one file into the binary file object it is given (seekable: LAS/LAZ need it)."""


class Sink(Protocol):
    """Where a scan's files go: a folder, an object store, a test's dict."""

    def put(self, name: str, data: bytes | Writer, media_type: str) -> None:
        """Store the file `name` (e.g. ``cloud.laz``): its bytes, or a `Writer` to call with a
        binary file object to write it into, served as `media_type`."""


def overlay_media_type(fmt: str = DEFAULT_OVERLAY_FORMAT) -> str:
    """The media type of the overlay picture in `fmt` (image/jpeg for jpeg)."""
    return mimetypes.guess_type(overlay_name("overlay", fmt))[0] or "application/octet-stream"


def report_bytes(report: ScanReport | Mapping[str, Any]) -> bytes:
    """report.json's bytes: the report (`prismcore.report.report_dict`) indented by 2, with a
    final newline."""
    content = report_dict(report) if isinstance(report, ScanReport) else report
    return (json.dumps(content, indent=2) + "\n").encode()


def write_outputs(result: ScanResult, sink: Sink, *, spec: ScanSpec, images: Sequence[np.ndarray],
                  overlay_format: str = DEFAULT_OVERLAY_FORMAT, overlay_max_side: int | None = None,
                  preview: bool = False, report: bool = True) -> dict[str, str]:
    """Put the formats the spec asks for, the overlay of the fit on each photo and report.json
    into `sink`; returns {kind: file name}, a kind per file put, in the order they were put.

    Parameters
    ----------
    result : ScanResult
        The scan; the writers' timings go into its report's `timings_ms` (``write_{kind}``, and
        ``write_overlay`` for the overlays, sink's time included).
    spec : ScanSpec
        Its `formats` (`prismcore.formats.output_files`: step and drawing write several files) and
        output options (CSV header and colours, ASCII PLY).
    images : sequence of ndarray
        The front photo, and the side photo in two-photo mode, as decoded: the glb model is
        textured from them and the overlays drawn on them.
    overlay_format : str
        The overlays' picture format: jpeg (overlay.jpg), png or webp.
    overlay_max_side : int, optional
        The overlays shrunk (area-averaged) to at most this many pixels along their longer side
        (a picture to look at, not a measurement); None: at the photo's size.
    preview : bool
        Also ``preview.ply``: the cloud thinned for a browser (`prismcore.scan.cloud.decimate`).
    report : bool
        Also report.json, last; False for a caller that adds to the report (its total time)
        first and puts it with `report_bytes`.
    """
    names: dict[str, str] = {}
    for kind in output_files(spec.formats):
        spent: list[float] = []

        def write(dest: BinaryIO, kind: str = kind, spent: list[float] = spent) -> None:
            spent.append(write_format(kind, dest, result.cloud, spec, report=result.report, images=images))

        names[kind] = FILE_NAMES[kind]
        sink.put(names[kind], write, media_type(kind))
        result.report.timings_ms[f"write_{kind}"] = round(spent[0], 3)
    if preview:
        _put_preview(result, sink, names, spec)
    started = time.perf_counter()
    two = spec.two_photo and (result.report.inputs or {}).get("side_image") and len(images) > 1
    for kind, photo in (("overlay", "front"), ("overlay_side", "side"))[:2 if two else 1]:
        picture = overlay_from_report(images[0 if photo == "front" else 1], result.report, photo=photo)
        if overlay_max_side is not None:
            picture = display_size(picture, overlay_max_side)
        names[kind] = overlay_name(kind, overlay_format)
        sink.put(names[kind], encode_overlay(picture, overlay_format), overlay_media_type(overlay_format))
    result.report.timings_ms["write_overlay"] = round((time.perf_counter() - started) * 1000, 3)
    if report:
        names["report"] = FILE_NAMES["report"]
        sink.put(names["report"], report_bytes(result.report), media_type("report"))
    return names


def _put_preview(result: ScanResult, sink: Sink, names: dict[str, str], spec: ScanSpec) -> None:
    """preview.ply: at most `prismcore.scan.cloud.PREVIEW_POINTS` points, by an even stride. A
    cloud that small is its own preview: where cloud.ply was put (binary), the preview is that
    file, not the same bytes put again (a 1 mm cloud's 0.3-0.7 MB, a sixth of a service item's
    requests and a quarter of its bytes)."""
    from prismcore.outputs.writers import write_ply
    from prismcore.scan.cloud import decimate

    thinned = decimate(result.cloud)
    if thinned is result.cloud and "ply" in names and not spec.ply_ascii:
        names["preview"] = names["ply"]
        return
    names["preview"] = FILE_NAMES["preview"]
    sink.put(names["preview"], lambda f: write_ply(f, thinned.points, thinned.colors), media_type("preview"))


def write_part_files(report: Mapping[str, Any], formats: Sequence[str], sink: Sink, *,
                     when: datetime | None = None) -> dict[str, str]:
    """Put the part's files of `formats` (step, drawing), written from the measurement `report`
    alone (a joint fit's, which makes no cloud), into `sink`; returns {kind: file name}."""
    names: dict[str, str] = {}
    for kind in output_files(formats):
        names[kind] = FILE_NAMES[kind]
        sink.put(names[kind], partial(write_part, kind, report=report, when=when), media_type(kind))
    return names


def display_size(picture: np.ndarray, max_side: int) -> np.ndarray:
    """`picture` (H, W, 3) uint8 shrunk (area-averaged) to at most `max_side` px along its
    longer side; as it is when already that small."""
    h, w = picture.shape[:2]
    if max(h, w) <= max_side:
        return picture
    import cv2  # here: writing clouds needs no OpenCV

    scale = max_side / max(h, w)
    resized: np.ndarray = cv2.resize(picture, (max(1, round(w * scale)), max(1, round(h * scale))),
                                     interpolation=cv2.INTER_AREA)
    return resized

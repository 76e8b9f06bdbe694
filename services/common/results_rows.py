"""The results table's rows and their CSV and JSON: one row per measured photo (or video frame),
the same columns for the service's job (``GET /v1/jobs/{id}/results.csv``, `prism_api.results_table`)
and for a batch `prism scan` measures locally (`prism_cli.scan_batch`), built by `result_row` alone.

Columns (`COLUMNS`; the JSON rows have the same keys, with numbers as numbers and null for
empty): the job and its client reference (empty for a local batch), the item, the item's own
reference (the client's id for that photo), the frame (empty on an item's row), the file name
the client sent (the upload's name; a local batch's photo's name), the input (the item's image
reference, or the photo's path), state and error (the failure's reason in words); width,
height, depth, their unit and one standard deviation each; the cloud's point count, the point
loss, where the reference points came from (clicked, auto: found in the photo, station or board:
derived from the part found on the support, tracked: carried from the marked frame of a video),
the search's confidence (auto) and the points p1..p7 (x, y px; those of the spec when the scan did
not record its own); the part's verdict and each dimension's verdict and deviation (mm) against
the nominal size (empty without one); on a station, its verification as the item stands (verified,
not verified, verified before the camera moved), the day of the verification that status comes
from, how far the camera moved since calibration (px, and mm on the support) and whether that
move asks for the station's re-verification; the measurement's warnings, joined by
`WARNINGS_JOIN`.

In the CSV, a text cell a spreadsheet would take for a formula (starting with =, +, -, @, a tab
or a carriage return: a client_reference of ``=1+2``, say) is written with a single quote before
it (OWASP's advice on CSV injection); numbers, negative ones included, are written as numbers.
The JSON keeps every value exactly as given.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Iterator
from typing import Any

from prismcore.spec import ReferencePoints, ScanSpec

from .records import ItemResult

__all__ = ["COLUMNS", "WARNINGS_JOIN", "Row", "csv_chunks", "json_chunks", "result_row"]

_DIMS = ("width", "height", "depth")
_POINTS = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
COLUMNS: tuple[str, ...] = (
    "job_id", "client_reference", "item", "item_reference", "frame", "file_name", "input", "state",
    "error", *_DIMS, "unit", *(f"{d}_sigma" for d in _DIMS),
    "cloud_points", "point_loss", "points_source", "points_confidence",
    *(f"{p}_{c}" for p in _POINTS for c in "xy"),
    "verdict", *(f"{d}_verdict" for d in _DIMS), *(f"{d}_deviation_mm" for d in _DIMS),
    "station_verification", "station_verification_date", "camera_shift_px", "camera_shift_mm",
    "station_reverify", "warnings",
)

WARNINGS_JOIN = " | "
"""Between two warnings in the `warnings` cell."""

Row = dict[str, Any]


def _spec_points(spec: ScanSpec, frame: int | None) -> ReferencePoints | None:
    if frame is not None and spec.frame_points:
        return spec.frame_points.get(frame, spec.points)
    return spec.points


def _points_source(spec: ScanSpec | None, frame: int | None, result: ItemResult | None) -> str:
    """Where the points came from, truthfully: a tracked video's frames were tracked (but the
    frame they were marked on), else the scan's own word; without a result (a failed item), where
    they would have come from, by its kind (a station's are found against its support)."""
    if spec is None:  # a photo measured on a station's file (prism scan --station)
        return result.points_source if result and result.points_source else "station"
    if spec.kind in ("tracked", "tracked_joint") and frame != spec.points_frame:
        return "tracked"
    if result and result.points_source:
        return result.points_source
    return "station" if spec.kind == "station" else "auto" if spec.auto_points is not None else "clicked"


def result_row(*, spec: ScanSpec | None, state: str, error: str | None, result: ItemResult | None,
               input: str | None = None, file_name: str | None = None, job_id: str | None = None,
               client_reference: str | None = None, item: int | None = None,
               item_reference: str | None = None, frame: int | None = None) -> Row:
    """One row of the table: a measured item's (or a video frame's, `frame`), from its spec (None
    for a photo measured on a station's file), its state, its error in words and its result
    (None until it succeeded). `input` defaults to the spec's image."""
    row: Row = dict.fromkeys(COLUMNS)
    row.update(job_id=job_id, client_reference=client_reference, item=item,
               item_reference=item_reference, frame=frame, file_name=file_name,
               input=input if input is not None or spec is None else spec.image, state=state, error=error)
    points: dict[str, Any] | None = result.reference_points if result else None
    if points is None and spec is not None and (given := _spec_points(spec, frame)) is not None:
        points = {k: list(v) for k, v in given.as_dict().items()}
    for name, xy in (points or {}).items():
        if name in _POINTS and xy is not None:
            row[f"{name}_x"], row[f"{name}_y"] = xy[0], xy[1]
    row["points_source"] = _points_source(spec, frame, result)
    if result is None:
        return row
    row["points_confidence"] = result.points_confidence
    row.update(cloud_points=result.points, point_loss=result.point_loss,
               unit=result.dimensions.get("unit"))
    for d in _DIMS:
        row[d] = result.dimensions.get(d)
        row[f"{d}_sigma"] = (result.uncertainty or {}).get(d)
    if result.station:  # measured on a station: its verification as this item stands, the drift
        status, moved = result.station["verification"], result.station["drift"]
        row["station_verification"] = status["status"]
        date = status.get("date")  # ISO date and time (UTC); the day is what the status names
        row["station_verification_date"] = date[:10] if isinstance(date, str) else None
        row["camera_shift_px"] = moved["shift_px"]
        row["camera_shift_mm"] = moved["shift_mm"]
        row["station_reverify"] = moved.get("reverify")
    quality = result.quality or {}
    row["verdict"] = quality.get("verdict")
    for d, judged in (quality.get("dimensions") or {}).items():
        if d in _DIMS:
            row[f"{d}_verdict"] = judged.get("verdict")
            row[f"{d}_deviation_mm"] = judged.get("deviation_mm")
    row["warnings"] = WARNINGS_JOIN.join(result.warnings) or None
    return row


_FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def _csv_cell(value: Any) -> Any:
    """`value` as a spreadsheet reads it as text: a string that would start a formula gets a
    leading single quote (numbers pass as they are)."""
    if isinstance(value, str) and value.startswith(_FORMULA_STARTS):
        return "'" + value
    return value


def csv_chunks(pages: Iterable[Iterable[Row]]) -> Iterator[str]:
    """The table as CSV text (RFC 4180), a header line then one chunk per page of rows."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\r\n")

    def flush() -> str:
        text = buffer.getvalue()
        buffer.seek(0)
        buffer.truncate()
        return text

    writer.writeheader()
    yield flush()
    for rows in pages:
        writer.writerows({k: _csv_cell(v) for k, v in row.items()} for row in rows)
        yield flush()


def json_chunks(head: dict[str, Any], pages: Iterable[Iterable[Row]]) -> Iterator[str]:
    """The table as one JSON document: `head`'s keys, ``columns`` and ``rows`` (a list of row
    objects), written a page at a time."""
    opening = json.dumps({**head, "columns": list(COLUMNS)})
    yield opening[:-1] + ', "rows": ['
    first = True
    for rows in pages:
        parts = [json.dumps(row) for row in rows]
        if parts:
            yield ("" if first else ", ") + ", ".join(parts)
            first = False
    yield "]}"

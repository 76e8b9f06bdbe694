"""One table per job: a row per item, and a row per frame of a video item (after its item's row).

The rows of ``GET /v1/jobs/{id}/results.csv`` and ``results.json``, built from the job store's
records (the item results the worker recorded), never from the reports in the bucket. A job is
read a page of items at a time, so a 10,000-item job's table streams without being held whole.

Columns (`COLUMNS`; the JSON rows have the same keys, with numbers as numbers and null for
empty): the job and its client reference, the item and frame (empty on an item's row), the
input (the item's image reference), state and error; width, height, depth, their unit and one
standard deviation each; the cloud's point count, the point loss, where the reference points
came from (clicked, auto, station), the search's confidence (auto) and the points p1..p7 (x, y px;
those of the spec when the scan did not record its own); the part's verdict and each
dimension's verdict and deviation (mm) against the nominal size (empty without one); on a station,
its verification as the item stands (verified, not verified, verified before the camera moved),
the date of the verification that status comes from (empty when the station has none), how far
the camera moved since calibration (px, and mm on the support) and whether that move asks for
the station's re-verification.

In the CSV, a text cell a spreadsheet would take for a formula (starting with =, +, -, @, a tab
or a carriage return: a client_reference of ``=1+2``, say) is written with a single quote before
it (OWASP's advice on CSV injection); numbers, negative ones included, are written as numbers.
The JSON keeps every value exactly as given.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from prism_common.records import ItemRecord, ItemResult, JobRecord, State

from prismcore.spec import ReferencePoints, ScanSpec

__all__ = ["COLUMNS", "PAGE_ITEMS", "csv_chunks", "item_rows", "json_chunks", "pages"]

PAGE_ITEMS = 200
"""Items read from the store per page (a video item brings its frames along)."""

_DIMS = ("width", "height", "depth")
_POINTS = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
COLUMNS: tuple[str, ...] = (
    "job_id", "client_reference", "item", "frame", "input", "state", "error",
    *_DIMS, "unit", *(f"{d}_sigma" for d in _DIMS),
    "cloud_points", "point_loss", "points_source", "points_confidence",
    *(f"{p}_{c}" for p in _POINTS for c in "xy"),
    "verdict", *(f"{d}_verdict" for d in _DIMS), *(f"{d}_deviation_mm" for d in _DIMS),
    "station_verification", "station_verification_date", "camera_shift_px", "camera_shift_mm",
    "station_reverify",
)

Row = dict[str, Any]
PageReader = Callable[[int, int], JobRecord | None]
"""(offset, limit) -> the job holding only those items, or None if the job is gone."""


def pages(first: JobRecord, n_items: int, read: PageReader, page_items: int = PAGE_ITEMS
          ) -> Iterator[JobRecord]:
    """`first` (the page at offset 0, read to answer 404 before streaming), then the following
    pages of `page_items` items through `read`, until `n_items` (stops early if the job is gone)."""
    yield first
    for offset in range(len(first.items), n_items, page_items):
        page = read(offset, page_items)
        if page is None or not page.items:
            return
        yield page


def item_rows(job: JobRecord) -> Iterator[Row]:
    """The rows of the items `job` holds: each item's, then its frames' in frame order."""
    for item in job.items:
        yield _row(job, item, None, item.state, item.error, item.result)
        for frame in item.frames:
            yield _row(job, item, frame.index, frame.state, frame.error, frame.result)


def _spec_points(spec: ScanSpec, frame: int | None) -> ReferencePoints | None:
    if frame is not None and spec.frame_points:
        return spec.frame_points.get(frame, spec.points)
    return spec.points


def _row(job: JobRecord, item: ItemRecord, frame: int | None, state: State, error: str | None,
         result: ItemResult | None) -> Row:
    spec = item.spec
    row: Row = dict.fromkeys(COLUMNS)
    row.update(job_id=job.id, client_reference=job.client_reference, item=item.index, frame=frame,
               input=spec.image, state=state.value, error=error)
    points: dict[str, Any] | None = result.reference_points if result else None
    if points is None and (given := _spec_points(spec, frame)) is not None:
        points = {k: list(v) for k, v in given.as_dict().items()}
    for name, xy in (points or {}).items():
        if name in _POINTS and xy is not None:
            row[f"{name}_x"], row[f"{name}_y"] = xy[0], xy[1]
    # Without a result (a failed item), where its points would have come from, by its kind: a
    # station's are found against its support, never clicked.
    row["points_source"] = (result.points_source if result and result.points_source
                            else "station" if spec.kind == "station"
                            else "auto" if spec.auto_points is not None else "clicked")
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
    return row


_FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def _csv_cell(value: Any) -> Any:
    """`value` as a spreadsheet reads it as text: a string that would start a formula gets a
    leading single quote (numbers pass as they are)."""
    if isinstance(value, str) and value.startswith(_FORMULA_STARTS):
        return "'" + value
    return value


def csv_chunks(jobs: Iterable[JobRecord]) -> Iterator[str]:
    """The table as CSV text, a header line then one chunk per page of items."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\r\n")  # RFC 4180's

    def flush() -> str:
        text = buffer.getvalue()
        buffer.seek(0)
        buffer.truncate()
        return text

    writer.writeheader()
    yield flush()
    for job in jobs:
        writer.writerows({k: _csv_cell(v) for k, v in row.items()} for row in item_rows(job))
        yield flush()


def json_chunks(head: dict[str, Any], jobs: Iterable[JobRecord]) -> Iterator[str]:
    """The table as one JSON document: `head`'s keys, ``columns`` and ``rows`` (a list of row
    objects), written a page at a time."""
    opening = json.dumps({**head, "columns": list(COLUMNS)})
    yield opening[:-1] + ', "rows": ['
    first = True
    for job in jobs:
        parts = [json.dumps(row) for row in item_rows(job)]
        if parts:
            yield ("" if first else ", ") + ", ".join(parts)
            first = False
    yield "]}"

"""One table per job: a row per item, and a row per frame of a video item (after its item's row).

The rows of ``GET /v1/jobs/{id}/results.csv`` and ``results.json``, built from the job store's
records (the item results the worker recorded), never from the reports in the bucket. A job is
read a page of items at a time, so a 10,000-item job's table streams without being held whole.
The columns, each row and the CSV and JSON text are `prism_common.results_rows`'s, which
`prism scan`'s local batch shares.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

from prism_common.records import ItemRecord, ItemResult, JobRecord, State
from prism_common.results_rows import COLUMNS, Row, result_row
from prism_common.results_rows import csv_chunks as _row_csv
from prism_common.results_rows import json_chunks as _row_json

__all__ = ["COLUMNS", "PAGE_ITEMS", "csv_chunks", "item_rows", "json_chunks", "pages"]

PAGE_ITEMS = 200
"""Items read from the store per page (a video item brings its frames along)."""

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


def _row(job: JobRecord, item: ItemRecord, frame: int | None, state: State, error: str | None,
         result: ItemResult | None) -> Row:
    return result_row(spec=item.spec, state=state.value, error=error, result=result,
                      file_name=item.file_name, job_id=job.id, client_reference=job.client_reference,
                      item=item.index, item_reference=item.spec.reference, frame=frame)


def csv_chunks(jobs: Iterable[JobRecord]) -> Iterator[str]:
    """The table as CSV text, a header line then one chunk per page of items."""
    return _row_csv(item_rows(job) for job in jobs)


def json_chunks(head: dict[str, Any], jobs: Iterable[JobRecord]) -> Iterator[str]:
    """The table as one JSON document: `head`'s keys, ``columns`` and ``rows`` (a list of row
    objects), written a page at a time."""
    return _row_json(head, (item_rows(job) for job in jobs))

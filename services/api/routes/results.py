"""One table per job: ``GET /v1/jobs/{id}/results.csv`` and ``results.json`` (`results_table`).

Streamed a page of items at a time; the first page is read before the answer starts, so an
unknown job (or another tenant's) answers 404 as every job route does.
"""

from __future__ import annotations

from collections.abc import Iterator

from fastapi import APIRouter
from fastapi.responses import StreamingResponse
from prism_common.records import JobRecord
from prism_common.store import JobStore

from ..deps import StoreDep, TenantDep
from ..results_table import PAGE_ITEMS, csv_chunks, json_chunks, pages
from .jobs import own_page

__all__ = ["router"]

router = APIRouter(prefix="/jobs", tags=["jobs"])

_ROWS = ("One row per item, then one per frame of a video item; columns: see `results.json`'s "
         "`columns`.")


def _pages(store: JobStore, job_id: str, tenant: str) -> tuple[JobRecord, Iterator[JobRecord]]:
    """The job's first page (404 if none of the tenant's), and every page from it on."""
    first, n_items = own_page(store, job_id, tenant, 0, PAGE_ITEMS)

    def read(offset: int, limit: int) -> JobRecord | None:
        page = store.get_page(job_id, offset, limit)
        return page[0] if page else None

    return first, pages(first, n_items, read)


def _attachment(job_id: str, name: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{job_id[:8]}-{name}"'}


@router.get("/{job_id}/results.csv", response_class=StreamingResponse,
            responses={200: {"content": {"text/csv": {}}, "description": _ROWS},
                       404: {"description": "No such job"}})
def results_csv(job_id: str, tenant: TenantDep, store: StoreDep) -> StreamingResponse:
    """The job's results as a CSV table (RFC 4180, a header line first)."""
    _, rows = _pages(store, job_id, tenant)
    return StreamingResponse(csv_chunks(rows), media_type="text/csv; charset=utf-8",
                             headers=_attachment(job_id, "results.csv"))


@router.get("/{job_id}/results.json", response_class=StreamingResponse,
            responses={200: {"content": {"application/json": {}}, "description": _ROWS},
                       404: {"description": "No such job"}})
def results_json(job_id: str, tenant: TenantDep, store: StoreDep) -> StreamingResponse:
    """The job's results as JSON: job_id, client_reference, state, verdicts, columns, rows."""
    first, rows = _pages(store, job_id, tenant)
    head = {"job_id": first.id, "client_reference": first.client_reference,
            "state": first.state.value, "verdicts": first.verdicts}
    return StreamingResponse(json_chunks(head, rows), media_type="application/json")

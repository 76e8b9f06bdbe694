"""Checks of a submitted job that need the settings or the store, beyond its schema.

Failures are reported like schema errors (422, one entry per problem with its location), so a
client handles both the same way.
"""

from __future__ import annotations

from typing import Any

from fastapi.exceptions import RequestValidationError
from prism_common.outbound import check_webhook_url
from prism_common.references import ReferenceError, check_reference, parse_reference
from prism_common.settings import Settings
from prism_common.store import JobStore

from .schemas import JobCreate

__all__ = ["check_job"]

_MAX_REPORTED = 50  # a 5000-item batch with one bad upload gets a readable answer, not 5000 lines


def check_job(job: JobCreate, settings: Settings, store: JobStore, tenant: str) -> set[str]:
    """Raise RequestValidationError naming every item (and field) the service will not run;
    else return the ids of the uploads the job reads."""
    errors: list[dict[str, Any]] = []

    def fail(loc: tuple, msg: str) -> None:
        errors.append({"type": "value_error", "loc": ("body", *loc), "msg": msg})

    if len(job.items) > settings.max_items_per_job:
        fail(("items",), f"at most {settings.max_items_per_job} items per job, got {len(job.items)}")
    if job.webhook_url is not None:
        try:  # the worker checks again before each delivery, resolving the host then
            check_webhook_url(job.webhook_url, settings, resolve=False)
        except ReferenceError as exc:
            fail(("webhook_url",), f"webhook_url: {exc}")
    # Explicit frame indices are known now; other selections are counted when the video is read.
    named = sum(len(item.frames.indices) for item in job.items if item.frames and item.frames.indices)
    if named > settings.max_frames_per_job:
        fail(("items",), f"the job's videos name {named} frames, over the cap of "
                         f"{settings.max_frames_per_job} frames per job")
    owners: dict[str, str | None] = {}  # a batch often reuses one upload: look it up once
    for i, item in enumerate(job.items):
        if len(errors) >= _MAX_REPORTED:
            break
        for field in ("image", "side_image"):
            text = getattr(item, field)
            if text is None:
                continue
            try:
                ref = parse_reference(text)
                if ref.kind == "upload" and ref.upload_id not in owners:
                    upload = store.get_upload(ref.upload_id)
                    owners[ref.upload_id] = upload["tenant"] if upload else None
                check_reference(ref, settings, tenant=tenant, upload_owner=owners.get(ref.upload_id))
            except ReferenceError as exc:
                fail(("items", i, field), f"item {i} {field}: {exc}")
    if errors:
        raise RequestValidationError(errors[:_MAX_REPORTED])
    return set(owners)

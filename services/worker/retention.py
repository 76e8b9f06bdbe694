"""Expiry of uploads (the file, a video's probe and decoded frames, the record) and, when the
operator sets a lifetime for them, of ended jobs (every object under jobs/{id}/, the record).

Run by the watchdog's sweep (one per interval across all workers). Objects go before records,
so a sweep cut short leaves the thing listed and the next one finishes it; deleting twice is
harmless. An upload's expiry does not touch the outputs of the jobs that read it.
"""

from __future__ import annotations

import logging

from prism_common.settings import Settings
from prism_common.storage import object_key
from prism_common.upload_keys import upload_key, video_info_key

from . import context

__all__ = ["expire_jobs", "expire_uploads"]

log = logging.getLogger(__name__)
_indexed = False


def expire_uploads(settings: Settings, now: float) -> int:
    """Delete the uploads older than `settings.upload_ttl_s` at `now` (s); how many went."""
    if settings.upload_ttl_s <= 0:
        return 0
    store, objects = context.store(), context.objects()
    global _indexed
    if not _indexed:  # once per process: uploads made before they were listed for expiry
        if added := store.index_old_uploads():
            log.info("listed %d older uploads for expiry", added)
        _indexed = True
    gone = 0
    for upload_id in store.uploads_before(now - settings.upload_ttl_s):
        upload = store.get_upload(upload_id)
        if upload is not None:
            tenant = upload["tenant"]
            frames = objects.list_keys(upload_key(tenant, upload_id) + ".frames/")
            objects.delete_keys([upload["key"], video_info_key(tenant, upload_id), *frames])
        store.delete_upload(upload_id)
        gone += 1
    if gone:
        log.info("deleted %d uploads older than %d s", gone, settings.upload_ttl_s)
    return gone


def expire_jobs(settings: Settings, now: float) -> int:
    """Delete the ended jobs submitted more than `settings.job_ttl_s` before `now` (s)."""
    if settings.job_ttl_s <= 0:
        return 0
    store, objects = context.store(), context.objects()
    gone = 0
    for job_id in store.ended_before(now - settings.job_ttl_s):
        objects.delete_keys(objects.list_keys(object_key("jobs", job_id) + "/"))
        gone += store.delete_job(job_id)
    if gone:
        log.info("deleted %d jobs submitted more than %d s ago", gone, settings.job_ttl_s)
    return gone

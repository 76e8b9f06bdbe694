"""Expiry of uploads: the uploaded file, a video's probe and its decoded frames, then the record.

Run by the watchdog's sweep (one per interval across all workers). Objects go before the record,
so a sweep cut short leaves the upload listed and the next one finishes it; deleting twice is
harmless. A job's own outputs are not touched: they live under its prefix, not the upload's.
"""

from __future__ import annotations

import logging

from prism_common.settings import Settings
from prism_common.upload_keys import upload_key, video_info_key

from . import context

__all__ = ["expire_uploads"]

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

"""Objects of the service's bucket streamed through the API, for the web page.

The page must fetch from its own origin with the caller's key (presigned URLs point at the S3
server, another origin), so some routes relay objects: in chunks, never whole in memory.
"""

from __future__ import annotations

from collections.abc import Iterator

from botocore.exceptions import ClientError
from botocore.response import StreamingBody
from fastapi.responses import StreamingResponse
from prism_common.storage import ObjectStore, is_missing

__all__ = ["CHUNK_BYTES", "relay_object"]

CHUNK_BYTES = 1 << 20


def _chunks(body: StreamingBody) -> Iterator[bytes]:
    try:
        yield from body.iter_chunks(CHUNK_BYTES)
    finally:
        body.close()


def relay_object(objects: ObjectStore, key: str, media_type: str, *,
                 max_age_s: int) -> StreamingResponse | None:
    """The object as a streamed response (private cache for `max_age_s`), or None when missing."""
    try:
        body, size = objects.open(key)
    except ClientError as exc:
        if is_missing(exc):
            return None
        raise
    return StreamingResponse(_chunks(body), media_type=media_type, headers={
        "Content-Length": str(size), "Cache-Control": f"private, max-age={max_age_s}"})

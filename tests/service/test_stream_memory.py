"""An upload of unknown size (a request body, read as it arrives) is held a few parts at a time
by the store's client, however far the client could read ahead of a slow store: against the
real SeaweedFS of the fixtures, the store's answers to each part delayed."""

from __future__ import annotations

import time
from typing import Any

PART = 8 * 2**20  # s3transfer's part of a multipart upload (its multipart_chunksize)


class Unseekable:
    """`size` bytes offered as fast as they are asked for, by read() alone (as a request body
    is); counts what has been read."""

    def __init__(self, size: int) -> None:
        self.left, self.read_bytes = size, 0
        self.ahead: list[int] = []  # at each read, the bytes read and not yet stored
        self.stored = 0

    def read(self, size: int = -1) -> bytes:
        size = self.left if size is None or size < 0 else min(size, self.left)
        self.left -= size
        self.read_bytes += size
        self.ahead.append(self.read_bytes - self.stored)
        return b"\x5a" * size


def test_a_stream_is_held_a_few_parts_at_a_time_while_the_store_is_slow(objects):
    parts = 12
    stream = Unseekable(parts * PART)

    def slow(**_: Any) -> None:
        time.sleep(0.3)  # a store slower than the client: the reader would run ahead of it

    def stored(http_response: Any, parsed: Any, **_: Any) -> None:
        if http_response.status_code == 200:
            stream.stored += PART

    events = objects.client.meta.events
    events.register("before-send.s3.UploadPart", slow)
    events.register("after-call.s3.UploadPart", stored)
    try:
        objects.put_stream("uploads/t/stream", stream)  # type: ignore[arg-type]
    finally:
        events.unregister("before-send.s3.UploadPart", slow)
        events.unregister("after-call.s3.UploadPart", stored)
    assert objects.client.head_object(Bucket=objects.bucket, Key="uploads/t/stream")["ContentLength"] \
        == parts * PART
    # Two parts queued or going up, one being read: s3transfer's default (10 in memory) let the
    # reader run up to 11 parts ahead
    assert max(stream.ahead) <= 3 * PART, [a / PART for a in stream.ahead]

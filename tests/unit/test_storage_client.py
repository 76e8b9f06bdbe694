"""The service's S3 client (`ObjectStore.from_settings`): what an upload sends, caught before it
leaves (botocore's before-send hook answers instead of a server).

Over plain http botocore would hash every body with SHA-256 for the signature; the client turns
that off (half of an upload's CPU) and keeps the body's CRC32 checksum (a header over http, a
trailer over https), which must be the CRC32 of the bytes sent (zlib's, the oracle).
"""

from __future__ import annotations

import base64
import io
import zlib
from typing import Any

import pytest
from botocore.awsrequest import AWSResponse
from prism_common.settings import Settings
from prism_common.storage import ObjectStore


class _Raw:
    """An empty response body, as urllib3's raw response streams it."""

    def stream(self, *_: Any, **__: Any) -> Any:
        return iter(())


def _store(endpoint: str) -> tuple[ObjectStore, list[Any]]:
    settings = Settings(api_keys={"t": "k" * 16}, webhook_secret="x" * 16, s3_endpoint_url=endpoint,
                        s3_access_key_id="key", s3_secret_access_key="secret")
    store = ObjectStore.from_settings(settings)
    sent: list[Any] = []

    def answer(request: Any, **_: Any) -> AWSResponse:
        sent.append(request)
        return AWSResponse(request.url, 200, {"ETag": '"0"'}, _Raw())

    store.client.meta.events.register("before-send.s3", answer)
    return store, sent


@pytest.mark.parametrize("endpoint", ["http://127.0.0.1:9", "https://127.0.0.1:9"])
@pytest.mark.parametrize("size", [0, 1, 70_000, 3 * 2**20 + 7])
@pytest.mark.parametrize("how", ["bytes", "stream"])
# An environment that asks for checksums only where required (set for older S3-compatible
# servers) must not leave an unsigned upload without its CRC32.
@pytest.mark.parametrize("env_checksums", [None, "when_required"])
def test_uploads_are_not_hashed_for_the_signature_and_carry_their_crc32(
        endpoint: str, size: int, how: str, env_checksums: str | None, monkeypatch) -> None:
    if env_checksums:
        monkeypatch.setenv("AWS_REQUEST_CHECKSUM_CALCULATION", env_checksums)
    store, sent = _store(endpoint)
    data = bytes((i * 7919) % 251 for i in range(size))
    if how == "bytes":
        store.put_bytes("jobs/j/items/0/cloud.laz", data)
    else:
        store.put_stream("jobs/j/items/0/cloud.laz", io.BytesIO(data))
    (request,) = sent
    body = request.body.read() if hasattr(request.body, "read") else request.body
    crc = base64.b64encode(zlib.crc32(data).to_bytes(4, "big"))
    if endpoint.startswith("http:"):  # the whole body, its checksum in a header
        assert request.headers["X-Amz-Content-SHA256"] == b"UNSIGNED-PAYLOAD"
        assert request.headers["x-amz-checksum-crc32"] == crc
        assert bytes(body or b"") == data
    else:  # botocore's own https way: aws-chunked, the checksum in a trailer
        assert request.headers["X-Amz-Content-SHA256"] == b"STREAMING-UNSIGNED-PAYLOAD-TRAILER"
        assert _unchunk(bytes(body)) == (data, {b"x-amz-checksum-crc32": crc})


def _unchunk(body: bytes) -> tuple[bytes, dict[bytes, bytes]]:
    """An aws-chunked body's data and trailers (hex size CRLF, data CRLF, ..., 0 CRLF, trailers)."""
    data, at = b"", 0
    while True:
        end = body.index(b"\r\n", at)
        size = int(body[at:end], 16)
        if size == 0:
            break
        data += body[end + 2:end + 2 + size]
        at = end + 2 + size + 2
    trailers = [line.split(b":", 1) for line in body[end + 2:].split(b"\r\n") if line]
    return data, {k: v for k, v in trailers}

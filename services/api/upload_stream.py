"""The file of a multipart upload as a plain file object, read straight off the request.

boto3 reads it (in its own threads) while the request body is still arriving, so an upload is
never held whole in memory or on disk (boto3 buffers one part, 8 MiB, at a time), and one over
the limit is refused as soon as the limit is passed, with the rest of the body left unread.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from typing import IO, Protocol

from anyio import from_thread
from anyio.lowlevel import EventLoopToken, current_token
from fastapi import HTTPException, Request, status
from python_multipart.exceptions import MultipartParseError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import ClientDisconnect

__all__ = ["HEAD_KEEP", "MULTIPART_OVERHEAD", "MultipartFile", "printable_name"]

MULTIPART_OVERHEAD = 64 * 1024  # boundaries, part headers and small extra fields beside the file
HEAD_KEEP = 1 << 20  # the file's first bytes, kept for the probe: a photo's header lies in them


class Watcher(Protocol):
    def feed(self, data: bytes) -> None: ...


def printable_name(name: str, limit: int = 200) -> str:
    """A name a client gave (an upload's file name, a station's name) as the service keeps it:
    only the characters `str.isprintable` takes (no NUL, CR, LF or other control character, no
    invisible format character such as a right-to-left override or isolate), stripped, at most
    `limit` characters; "" when nothing is left."""
    return "".join(c for c in name if c.isprintable()).strip()[:limit]


def _safe_name(raw: bytes | None) -> str:
    # Browsers send a bare name, other clients sometimes a path; keep the last segment, printable.
    name = (raw or b"").decode("utf-8", "replace").replace("\\", "/").rsplit("/", 1)[-1]
    return printable_name(name) or "upload"


class MultipartFile:
    """read() the part named `field` of the request's multipart body, at most `limit` bytes.

    Must be created on the event loop; read() may be called from any thread. A refusal
    (400, 413, 422) is raised from read() and kept in `failure`, since boto3 may wrap what it
    raises. The file's first `HEAD_KEEP` bytes are kept in `head`; `spool_when`, given the
    first bytes read, may return a file into which the whole file is then copied as it passes
    (a video, which can only be probed from a file); `watch_when`, likewise, an object whose
    feed() is given every byte (a photo's `ImageEnd`, which finds a file cut short).
    """

    def __init__(self, request: Request, field: str, limit: int, *,
                 spool_when: Callable[[bytes], IO[bytes] | None] | None = None,
                 watch_when: Callable[[bytes], Watcher | None] | None = None) -> None:
        kind, options = parse_options_header(request.headers.get("content-type", ""))
        if kind != b"multipart/form-data" or not options.get(b"boundary"):
            raise HTTPException(422, "send the file as multipart/form-data, field 'file'",
                                headers={"Connection": "close"})  # the body is left unread
        self._chunks = request.stream()
        self._token: EventLoopToken = current_token()
        self._field, self.limit = field.encode(), limit
        self._buf = bytearray()
        self._received = 0  # the whole body, extra fields included
        self._found = self._in_file = self._file_done = self._body_done = False
        self._header_field = self._header_value = b""
        self._disposition = b""
        self.size, self.name = 0, "upload"
        self.sha256 = hashlib.sha256()  # of the file's bytes, for finding the same upload again
        self.head = bytearray()
        self._spool_when = spool_when
        self.spool: IO[bytes] | None = None
        self._watch_when = watch_when
        self.watch: Watcher | None = None
        self.failure: HTTPException | None = None
        self._parser = MultipartParser(options[b"boundary"], callbacks={
            "on_part_begin": self._part_begin, "on_header_field": self._on_field,
            "on_header_value": self._on_value, "on_header_end": self._header_end,
            "on_headers_finished": self._headers_finished, "on_part_data": self._part_data,
            "on_part_end": self._part_end})

    # -- parser callbacks (on the event loop) ------------------------------------------------
    def _part_begin(self) -> None:
        self._disposition = b""

    def _on_field(self, data: bytes, start: int, end: int) -> None:
        self._header_field += data[start:end]

    def _on_value(self, data: bytes, start: int, end: int) -> None:
        self._header_value += data[start:end]

    def _header_end(self) -> None:
        if self._header_field.lower() == b"content-disposition":
            self._disposition = self._header_value
        self._header_field = self._header_value = b""

    def _headers_finished(self) -> None:
        _, options = parse_options_header(self._disposition)
        self._in_file = options.get(b"name") == self._field and not self._file_done
        if self._in_file:
            self._found, self.name = True, _safe_name(options.get(b"filename"))

    def _part_data(self, data: bytes, start: int, end: int) -> None:
        if self._in_file:
            self._buf += data[start:end]
            self.sha256.update(data[start:end])
            self.size += end - start

    def _part_end(self) -> None:
        if self._in_file:
            self._in_file, self._file_done = False, True

    # -- reading -----------------------------------------------------------------------------
    def _refuse(self, code: int, detail: str) -> HTTPException:
        # Connection: close, so the server drops the connection rather than draining the unread
        # rest of the body to keep it alive.
        self.failure = HTTPException(code, detail, headers={"Connection": "close"})
        return self.failure

    async def _fill(self, want: int) -> None:
        while len(self._buf) < want and not self._file_done:
            if self._body_done:
                raise self._refuse(422, "the multipart body ended before the 'file' part did"
                                   if self._found else "no 'file' part in the multipart body")
            try:
                chunk = await self._chunks.__anext__()
            except ClientDisconnect:
                raise self._refuse(400, "the client went away during the upload") from None
            self._received += len(chunk)
            if not chunk:
                self._body_done = True
                continue
            try:
                self._parser.write(chunk)
            except MultipartParseError as exc:
                raise self._refuse(422, f"malformed multipart body: {exc}") from None
            if self.size > self.limit or self._received > self.limit + MULTIPART_OVERHEAD:
                raise self._refuse(status.HTTP_413_CONTENT_TOO_LARGE,
                                   f"the upload is larger than {self.limit} bytes")

    async def aclose(self) -> None:
        await self._chunks.aclose()  # the rest of a refused body is left unread, on purpose

    def read(self, size: int = -1) -> bytes:
        if self.failure is not None:
            raise self.failure
        want = size if size is not None and size >= 0 else self.limit + 1
        from_thread.run(self._fill, want, token=self._token)
        out = bytes(self._buf[:want])
        del self._buf[:want]
        if not out and size != 0 and self.size == 0:
            raise self._refuse(422, "the uploaded file is empty")
        if out and not self.head and self._spool_when is not None:
            self.spool = self._spool_when(out)
        if out and not self.head and self._watch_when is not None:
            self.watch = self._watch_when(out)
        if self.watch is not None and out:
            self.watch.feed(out)
        if len(self.head) < HEAD_KEEP:
            self.head += out[: HEAD_KEEP - len(self.head)]
        if self.spool is not None and out:
            self.spool.write(out)
        return out

"""PRISM_UPLOADS_AT_ONCE: an API process takes that many uploads at once, and one more is refused
at once (503 at-capacity with Retry-After, its body not read by the route) rather than held; in
process on the real Redis and SeaweedFS of the fixtures."""

# ruff: noqa: F811 - `make_client` is test_api's fixture, imported to be used as such
from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import httpx
from prism_common.settings import get_settings

from prism_api.main import create_app

from .test_api import ACME, make_client, photo  # noqa: F401 (make_client: a fixture)

BOUNDARY = "b0undary"
MULTIPART = {**ACME, "Content-Type": f"multipart/form-data; boundary={BOUNDARY}"}


def _head(name: str) -> bytes:
    return (f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="{name}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n").encode()


_TAIL = f"\r\n--{BOUNDARY}--\r\n".encode()


async def _held(name: str, data: bytes, reading: anyio.Event, go: anyio.Event) -> AsyncIterator[bytes]:
    """A body whose file stops after its part's headers until `go`; `reading` is set when the
    app asks for more than them (it is in the route, holding one of the uploads)."""
    yield _head(name)
    reading.set()
    await go.wait()
    yield data + _TAIL


def test_uploads_past_the_cap_are_refused_unread_and_the_others_stored(settings, objects):
    app = create_app()
    app_settings = settings.model_copy(update={"uploads_at_once": 2})
    app.dependency_overrides[get_settings] = lambda: app_settings
    answers: dict[str, httpx.Response] = {}
    pulled = 0

    async def counted() -> AsyncIterator[bytes]:
        nonlocal pulled
        for chunk in (_head("third.png"), photo(2000) + _TAIL):
            pulled += 1
            yield chunk

    async def run() -> None:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://testserver",
                                     timeout=60) as http:

            async def post(name: str, body: AsyncIterator[bytes]) -> None:
                answers[name] = await http.post("/v1/uploads", content=body, headers=MULTIPART)

            go = anyio.Event()
            reading = [anyio.Event(), anyio.Event()]
            with anyio.fail_after(60):
                async with anyio.create_task_group() as tg:
                    for n, event in enumerate(reading):  # random padding: two distinct files
                        tg.start_soon(post, f"held{n}.png", _held(f"held{n}.png", photo(1000 + n), event, go))
                    for event in reading:
                        await event.wait()
                    await post("third.png", counted())  # both held uploads are in the route
                    go.set()
                # both gave their places back, and so do refused ones: 3 refusals in a row
                # would find none left after 2 leaked
                for n in range(3):
                    await post(f"text{n}", _text(n))
                await post("after.png", _one(photo(3000)))

    anyio.run(run)
    third = answers["third.png"]
    assert third.status_code == 503, third.text
    assert third.headers["content-type"] == "application/problem+json"
    # The connection is kept, the rest of the body dropped by the server: closed with the body
    # unread, it would be reset, and a client still sending would see the reset, not the 503.
    assert third.headers["Retry-After"] == "1" and "close" not in third.headers.get("Connection", "")
    problem = third.json()
    assert problem["type"].endswith("/at-capacity") and problem["status"] == 503, problem
    assert "2 uploads" in problem["detail"] and "PRISM_UPLOADS_AT_ONCE" in problem["detail"], problem
    assert pulled == 0  # refused on its headers: none of its body was read
    for name in ("held0.png", "held1.png", "after.png"):
        assert answers[name].status_code == 201, answers[name].text
    assert [answers[f"text{n}"].status_code for n in range(3)] == [415, 415, 415]
    stored = {answers[name].json()["id"] for name in ("held0.png", "held1.png", "after.png")}
    assert len(objects.list_keys("uploads/")) == len(stored) == 3


async def _one(data: bytes) -> AsyncIterator[bytes]:
    yield _head("after.png") + data + _TAIL


async def _text(n: int) -> AsyncIterator[bytes]:
    yield _head(f"notes{n}.txt") + b"just some notes\n" * 20 + _TAIL


def test_no_cap_when_set_to_zero(make_client):
    # 0 turns the cap off (as PRISM_QUEUE_MAX_DEPTH=0 does admission's): uploads are taken as before
    client = make_client(uploads_at_once=0)
    r = client.post("/v1/uploads", files={"file": ("a.png", photo())}, headers=ACME)
    assert r.status_code == 201, r.text

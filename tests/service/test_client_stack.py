"""The typed client against a real API under uvicorn: a 429 from the rate limit is waited out for
the Retry-After the API gives and the call then succeeds; a submit retried so carries one
Idempotency-Key, so exactly one job is made; a file named by many items is uploaded once."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from prism_cli.client import ApiClient
from prism_cli.stack import ManagedProcess, start_api

from .conftest import API_KEYS
from .servers import service_env
from .test_api import photo


@pytest.fixture(scope="module")
def api(redis_server, s3_server, tmp_path_factory) -> Iterator[ManagedProcess]:
    # 6 calls a minute: a burst of 6, then one every 10 s. So slow a refill is what makes the
    # submit below meet a 429 on a loaded machine too: at one a second (and Retry-After rounded
    # up to whole seconds) the bucket could refill between the last read and the submit, and
    # did on a fresh-clone CI run under load.
    env = service_env(redis_server.port, s3_server.port, db=12, bucket="t-client",
                      RATE_LIMIT_PER_MINUTE="6")
    proc = start_api(tmp_path_factory.mktemp("api"), env)
    yield proc
    proc.stop()


def test_a_429_is_waited_out_and_a_retried_submit_makes_one_job(api, tmp_path: Path):
    base = f"http://127.0.0.1:{api.port}"
    key = API_KEYS["acme"]
    waits: list[float] = []

    def sleep(seconds: float) -> None:
        waits.append(seconds)
        time.sleep(seconds)

    seen: list[httpx.Request] = []
    transport = httpx.HTTPTransport()

    class Recording(httpx.BaseTransport):
        def handle_request(self, request: httpx.Request) -> httpx.Response:
            seen.append(request)
            return transport.handle_request(request)

        def close(self) -> None:  # the client closes its transport: pass that on (its sockets)
            transport.close()

    file = tmp_path / "box.png"
    file.write_bytes(photo(width=400, height=300))
    with ApiClient(base, key, transport=Recording(), sleep=sleep) as client:
        reference = client.upload(file)
        for _ in range(10):  # spend the burst on cheap reads, until one met a 429
            client.jobs(limit=1)
            if waits:
                break
        assert any(w >= 1 for w in waits), waits  # 429s were answered with Retry-After and waited
        clicks = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]
        items = [{"image": client.upload(file), "points": clicks} for _ in range(5)]
        job = client.submit({"items": items, "client_reference": "retried"})
    uploads = [r for r in seen if r.url.path == "/v1/uploads"]
    assert len(uploads) == 1 and {i["image"] for i in items} == {reference}
    submits = [r for r in seen if r.url.path == "/v1/jobs" and r.method == "POST"]
    assert len(submits) >= 2  # the budget was spent: the submit met a 429 and was sent again
    assert len({r.headers["Idempotency-Key"] for r in submits}) == 1
    # The budget is spent: read through a client too, which waits out the 429s a bare GET met.
    with ApiClient(base, key, sleep=time.sleep) as reader:
        listed = reader.jobs(limit=200).jobs
    assert [j.id for j in listed if j.client_reference == "retried"] == [job.id]
    assert json.loads(submits[-1].content)["client_reference"] == "retried"

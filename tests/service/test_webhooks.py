"""Webhooks by the Standard Webhooks specification, against the real stack: the API under
uvicorn and Celery workers on the session's redis-server and SeaweedFS, delivering to receivers
on loopback that verify with the `standardwebhooks` package (the library a client would use).

The signature is also recomputed here by hand from the specification (HMAC-SHA256 over
``{id}.{timestamp}.{body}``, base64), and the signer reproduces the specification's published
test vector, so the library's own round trip is not the only check.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import hmac
import json
import os
import queue
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import httpx
import pytest
import redis
import standardwebhooks.webhooks
from prism_common.outbound import check_webhook_url
from prism_common.records import State
from prism_common.references import ReferenceError
from prism_common.settings import Settings
from prism_common.store import JobStore
from prism_common.webhook_secret import signing_key
from pydantic import ValidationError
from standardwebhooks import Webhook, WebhookVerificationError

from prism_cli.stack import ManagedProcess, start_api, start_worker
from prism_worker.webhooks import message_id, signed_headers
from prismsynth import Box, render_oblique_view

from .conftest import API_KEYS
from .servers import free_port, service_env, wait_for_port
from .worker_env import Env, encode, spec_for, worker_env

RECEIVER_PAGE = Path(__file__).resolve().parents[2] / "docs" / "how-to" / "webhooks.md"
ACME = {"X-API-Key": API_KEYS["acme"]}
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
# The standard's form of secret: "whsec_" + base64 of 32 key bytes.
KEY = hashlib.sha256(b"prism webhook tests").digest()
SECRET = "whsec_" + base64.b64encode(KEY).decode()
WORKER_TIMEOUT_S = 5.0  # prism_worker.webhooks.TIMEOUT: a receiver slower than this is retried
HANG_CAP_S = 60.0  # a "hang" answer waits for the worker to give up, at most this long
TOLERANCE = timedelta(minutes=5)  # the standard's replay window, as its libraries apply it


# -- receivers on loopback -------------------------------------------------------------------------

@dataclass(frozen=True)
class Delivery:
    headers: dict[str, str]  # names lowercased
    body: bytes
    received_at: float  # time.time() on arrival


class Receiver:
    """An HTTP server on 127.0.0.1 that records every POST and answers them in turn by `plan`:
    "ok" (204), "500", or "hang" (reads it, then no answer until the worker gives up and
    closes the connection: its timeout ends the attempt, however late a loaded machine fires it)."""

    def __init__(self, plan: tuple[str, ...] = ()) -> None:
        self.deliveries: list[Delivery] = []
        self.plan = list(plan)
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                outer.deliveries.append(Delivery({k.lower(): v for k, v in self.headers.items()},
                                                 body, time.time()))
                action = outer.plan.pop(0) if outer.plan else "ok"
                if action == "hang":
                    self.connection.settimeout(HANG_CAP_S)
                    with contextlib.suppress(OSError):
                        self.connection.recv(1)  # b"" once the worker has closed its end
                    return
                self.send_response(500 if action == "500" else 204)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server.server_address[1]}/hook"

    def wait(self, count: int, timeout: float = 40) -> list[Delivery]:
        deadline = time.monotonic() + timeout
        while len(self.deliveries) < count:
            assert time.monotonic() < deadline, f"{len(self.deliveries)} of {count} deliveries arrived"
            time.sleep(0.1)
        return self.deliveries[:count]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    made = Receiver()
    yield made
    made.close()


# -- the stack -------------------------------------------------------------------------------------

class Stack:
    """The API and a worker allowing http webhooks to loopback (a receiver on this machine)."""

    def __init__(self, api: ManagedProcess, worker: ManagedProcess) -> None:
        self.api, self.worker = api, worker
        self.http = httpx.Client(base_url=f"http://127.0.0.1:{api.port}", timeout=30)

    def upload(self, data: bytes) -> str:
        r = self.http.post("/v1/uploads", files={"file": ("box.png", data)}, headers=ACME)
        assert r.status_code in (200, 201), r.text  # 200: the same content again
        return r.json()["reference"]

    def submit(self, photo: str, scene, webhook_url: str) -> str:
        item = {"image": photo, "points": [list(map(round, scene.points[n])) for n in NAMES],
                "focal_px": scene.focal_px, "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}}
        r = self.http.post("/v1/jobs", json={"items": [item], "webhook_url": webhook_url}, headers=ACME)
        assert r.status_code == 202, r.text
        return r.json()["id"]

    def wait(self, job_id: str, timeout: float = 120) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            job = self.http.get(f"/v1/jobs/{job_id}", headers=ACME).json()
            if job["state"] in ("succeeded", "completed_with_failures", "failed", "cancelled"):
                return job
            time.sleep(0.25)
        raise AssertionError(f"job {job_id} not final after {timeout} s\n{self.worker.log[-3000:]}")


@pytest.fixture(scope="module")
def stack(redis_server, s3_server, tmp_path_factory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("webhooks")
    # VISIBILITY_TIMEOUT_S=10 caps the retry back-off at 5 s, so a retry comes within the test.
    env = service_env(redis_server.port, s3_server.port, db=14, bucket="t-webhooks",
                      WEBHOOK_SECRET=SECRET, WEBHOOK_ALLOWED_HOSTS='["127.0.0.1"]',
                      WEBHOOK_ALLOW_HTTP="true", WEBHOOK_ALLOW_PRIVATE="true",
                      TILES_PER_FACE="2", VISIBILITY_TIMEOUT_S="10")
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=2)
    made = Stack(api, worker)
    yield made
    made.http.close()
    worker.stop()
    api.stop()


@pytest.fixture(scope="module")
def scene():
    return render_oblique_view(Box(120.0, 80.0, 60.0), seed=1)


@pytest.fixture(scope="module")
def photo(stack, scene) -> str:
    return stack.upload(encode(scene.image))


@pytest.fixture(scope="module")
def delivered(stack, scene, photo) -> tuple[dict, Delivery]:
    """One real job's delivery, as the receiver got it, and the job as GET answers it after."""
    made = Receiver()
    try:
        job_id = stack.submit(photo, scene, made.url)
        job = stack.wait(job_id)
        (delivery,) = made.wait(1)
    finally:
        made.close()
    return job, delivery


def _spec_signature(key: bytes, headers: dict[str, str], body: bytes) -> str:
    """The signature as the specification defines it, computed without the library."""
    signed = f"{headers['webhook-id']}.{headers['webhook-timestamp']}.".encode() + body
    return "v1," + base64.b64encode(hmac.new(key, signed, hashlib.sha256).digest()).decode()


def _unsigned(job: dict) -> dict:
    """The job without the presigned links' query strings (their signing time differs)."""
    items = [{**item, "downloads": {k: url.split("?")[0] for k, url in item["downloads"].items()}}
             for item in job["items"]]
    return {**job, "items": items}


# -- deliveries ------------------------------------------------------------------------------------

def test_a_delivery_verifies_with_the_standard_library(delivered):
    job, delivery = delivered
    assert job["state"] == "succeeded", job
    headers, body = delivery.headers, delivery.body
    assert headers["webhook-id"] == f"job.finished.{job['id']}"
    assert headers["content-type"] == "application/json"
    # Signed when it was sent: after the job ended (its finished_at, the worker's clock), before
    # it arrived; whole seconds. Not within a fixed 2 s of its arrival: load between the
    # signing and the receiver's clock read is not the worker's doing.
    ended = datetime.fromisoformat(job["finished_at"]).timestamp()
    assert int(ended) <= int(headers["webhook-timestamp"]) <= delivery.received_at
    assert headers["webhook-signature"] == _spec_signature(KEY, headers, body)
    payload = Webhook(SECRET).verify(body, headers)
    assert payload == json.loads(body)
    # The very document GET answers; only the presigned links' signatures and expiry differ.
    assert _unsigned(payload) == _unsigned(job)
    item = payload["items"][0]
    assert set(item["downloads"]) == {"csv", "ply", "preview", "overlay", "report"}  # the default
    csv = httpx.get(item["downloads"]["csv"], timeout=10)  # presigned: no credentials needed
    assert csv.status_code == 200
    assert csv.content.count(b"\n") == item["result"]["points"]  # one line a point
    assert "x-prism-signature" not in headers  # the old scheme is gone


class _Clock(datetime):
    """The verifier's clock, set to `at`: the delivery's own signing time moved by a test's
    minutes (a receiver checking it that much later), so how long ago the module captured the
    delivery does not count (read from this machine's clock, 4 minutes was 5 once the capture
    was a minute old)."""

    at = datetime.fromtimestamp(0, UTC)

    @classmethod
    def now(cls, tz=None):  # type: ignore[override]
        return cls.at.astimezone(tz)


@pytest.mark.parametrize(("minutes", "refused"), [
    (0, None), (4, None), (-4, None), (6, "too old"), (60 * 24, "too old"), (-6, "too new")])
def test_a_replay_later_is_refused_by_the_verifier(delivered, monkeypatch, minutes, refused):
    _, delivery = delivered
    sent = datetime.fromtimestamp(int(delivery.headers["webhook-timestamp"]), tz=UTC)
    monkeypatch.setattr(_Clock, "at", sent + timedelta(minutes=minutes))
    monkeypatch.setattr(standardwebhooks.webhooks, "datetime", _Clock)
    # The oracle is the standard's 5-minute window around the signed timestamp.
    assert (abs(_Clock.now(UTC) - sent) > TOLERANCE) == (refused is not None)
    if refused is None:
        Webhook(SECRET).verify(delivery.body, delivery.headers)
    else:
        with pytest.raises(WebhookVerificationError, match=refused):
            Webhook(SECRET).verify(delivery.body, delivery.headers)


def _flip(data: bytes, at: int) -> bytes:
    return data[:at] + bytes([data[at] ^ 0x01]) + data[at + 1:]


TAMPERINGS = {
    "body-byte": lambda h, b: (h, _flip(b, len(b) // 2)),
    "body-appended": lambda h, b: (h, b + b" "),
    "state-rewritten": lambda h, b: (h, b.replace(b'"succeeded"', b'"failed"', 1)),
    "other-id": lambda h, b: ({**h, "webhook-id": "job.finished." + "0" * 32}, b),
    "timestamp-moved": lambda h, b: ({**h, "webhook-timestamp": str(int(h["webhook-timestamp"]) + 1)}, b),
    "other-key": lambda h, b: ({**h, "webhook-signature": _spec_signature(b"another key 0123456789", h, b)},
                               b),
    "no-signature": lambda h, b: ({k: v for k, v in h.items() if k != "webhook-signature"}, b),
}


@pytest.mark.parametrize("tampering", TAMPERINGS)
def test_an_altered_delivery_is_refused(delivered, tampering):
    _, delivery = delivered
    headers, body = TAMPERINGS[tampering](delivery.headers, delivery.body)
    assert (headers, body) != (delivery.headers, delivery.body)
    with pytest.raises(WebhookVerificationError):
        Webhook(SECRET).verify(body, headers)
    Webhook(SECRET).verify(delivery.body, delivery.headers)  # the original still passes


def test_a_retry_has_the_same_id_and_a_fresh_signature(stack, scene, photo, redis_server):
    # The first attempt gets no answer within the worker's timeout: the worker gives up on it
    # and tries again (Celery retry with back-off), signing the new attempt when it is sent.
    made = Receiver(plan=("hang", "ok"))
    store = JobStore(redis.Redis(port=redis_server.port, db=14, decode_responses=True))
    try:
        job_id = stack.submit(photo, scene, made.url)
        job = stack.wait(job_id)
        assert job["state"] == "succeeded"
        # Due from the job's ending (the watchdog would send a lost delivery again; the first
        # attempt hangs for seconds) until the delivery went through.
        assert job_id in store.webhooks_due(time.time() + 86400)
        first, second = made.wait(2, timeout=60)
        deadline = time.monotonic() + 60
        while job_id in store.webhooks_due(time.time() + 86400):
            assert time.monotonic() < deadline, "the delivered webhook is still due"
            time.sleep(0.1)
    finally:
        made.close()
    assert first.headers["webhook-id"] == second.headers["webhook-id"] == message_id(job_id)
    t1, t2 = (int(d.headers["webhook-timestamp"]) for d in (first, second))
    assert t2 - t1 >= WORKER_TIMEOUT_S - 1, (t1, t2)  # re-signed, not the first attempt resent
    # Each signed as it was sent (whole seconds): the first after the job ended, the second after
    # the first attempt had arrived; each before its own arrival (no fixed 2 s window, which load
    # between the signing and the receiver's clock read could pass).
    ended = datetime.fromisoformat(job["finished_at"]).timestamp()
    assert int(ended) <= t1 <= first.received_at, (ended, t1, first.received_at)
    assert int(first.received_at) <= t2 <= second.received_at, (first.received_at, t2, second.received_at)
    for delivery in (first, second):
        assert delivery.headers["webhook-signature"] == _spec_signature(KEY, delivery.headers, delivery.body)
        assert Webhook(SECRET).verify(delivery.body, delivery.headers)["id"] == job_id


# -- the docs' receiver -------------------------------------------------------------------------

def _readme_receiver() -> str:
    """The python block of the docs' webhooks how-to."""
    section = RECEIVER_PAGE.read_text()
    blocks = re.findall(r"^```python\n(.*?)^```$", section, re.S | re.M)
    assert len(blocks) == 1, f"docs/how-to/webhooks.md: {len(blocks)} python blocks"
    assert blocks[0].count("8080") == 1
    return blocks[0]


@pytest.fixture
def readme_receiver(tmp_path) -> Iterator[tuple[str, queue.Queue[str]]]:
    """The README's block running as written (port 8080 made free), its printed lines queued
    (its access log, on stderr, goes to a file)."""
    port = free_port()
    script = tmp_path / "receiver.py"
    script.write_text(_readme_receiver().replace("8080", str(port)))
    lines: queue.Queue[str] = queue.Queue()
    with (tmp_path / "stderr.log").open("w") as stderr, subprocess.Popen(
            [sys.executable, str(script)], env={**os.environ, "PRISM_WEBHOOK_SECRET": SECRET},
            stdout=subprocess.PIPE, stderr=stderr, text=True) as proc:
        assert proc.stdout is not None

        def read(stream=proc.stdout) -> None:
            for line in stream:
                lines.put(line.rstrip("\n"))

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            wait_for_port(port, timeout=60, proc=proc)
            yield f"http://127.0.0.1:{port}/hook", lines
        finally:
            proc.terminate()
            proc.wait(timeout=10)
            reader.join(timeout=10)  # it stops at the end of the output; Popen closes the pipe


def _post(url: str, delivery: Delivery) -> int:
    """Send a captured delivery again, as an attacker or a proxy would: its body and headers."""
    headers = {k: v for k, v in delivery.headers.items() if k.startswith("webhook-") or k == "content-type"}
    return httpx.post(url, content=delivery.body, headers=headers, timeout=10).status_code


def test_the_readme_receiver_verifies_real_deliveries(stack, scene, photo, delivered, readme_receiver):
    url, lines = readme_receiver
    job_id = stack.submit(photo, scene, url)  # a real delivery, straight from the worker
    assert stack.wait(job_id)["state"] == "succeeded"
    assert lines.get(timeout=60) == f"{job_id} succeeded"
    # A delivery captured earlier, resent now: verified, handled once, a repeat dropped by its id.
    job, captured = delivered
    assert _post(url, captured) == 204
    assert lines.get(timeout=10) == f"{job['id']} succeeded"
    assert _post(url, captured) == 204
    altered = replace(captured, body=captured.body.replace(b'"succeeded"', b'"failed"', 1))
    assert _post(url, altered) == 400
    assert lines.get(timeout=10).startswith("refused:")  # and not a second "succeeded" line
    assert lines.empty()


# -- the URL policy: one rule for the API and the worker -------------------------------------------

@pytest.fixture(scope="module")
def strict_api(redis_server, s3_server, tmp_path_factory) -> Iterator[httpx.Client]:
    """An API whose webhook rule is the default one: https only."""
    env = service_env(redis_server.port, s3_server.port, db=15, bucket="t-webhooks-strict",
                      WEBHOOK_ALLOWED_HOSTS='["127.0.0.1"]', WEBHOOK_ALLOW_PRIVATE="true")
    api = start_api(tmp_path_factory.mktemp("strict-api"), env)
    with httpx.Client(base_url=f"http://127.0.0.1:{api.port}", timeout=30) as client:
        yield client
    api.stop()


def _bad_fields(answer: dict) -> set[str]:
    """JSON pointers of the fields a 422 names (problem+json `errors`, or FastAPI's `detail`)."""
    if "errors" in answer:
        return {e.get("pointer", "") for e in answer["errors"]}
    return {"/" + "/".join(str(p) for p in e["loc"][1:]) for e in answer["detail"]}


# The rule, written out: (url, accepted with https only, accepted with http allowed too).
POLICY = [
    ("https://127.0.0.1/hook", True, True),
    ("https://127.0.0.1:8443/hook?x=1", True, True),
    ("http://127.0.0.1:8080/hook", False, True),
    ("HTTP://127.0.0.1/hook", False, True),
    ("https://hooks.example.com/hook", False, False),  # not on the allow-list
    ("http://hooks.example.com/hook", False, False),
    ("https://u:p@127.0.0.1/hook", False, False),
    ("ftp://127.0.0.1/hook", False, False),
    ("https://127.0.0.1:99999/hook", False, False),
    ("https:///hook", False, False),
    ("not a url", False, False),
]


@pytest.mark.parametrize(("url", "https_only", "http_too"), POLICY)
def test_the_api_applies_the_rule_at_submit(stack, strict_api, url, https_only, http_too):
    # The item names an upload that does not exist, so no job is ever made: the answer is 422
    # either way, and what is checked is whether it names webhook_url.
    job = {"items": [{"image": "upload:" + "0" * 32, "points": [[10, 10], [110, 12], [108, 80],
                                                               [150, 6], [200, 8]]}],
           "webhook_url": url}
    for client, accepted in ((strict_api, https_only), (stack.http, http_too)):
        r = client.post("/v1/jobs", json=job, headers=ACME)
        assert r.status_code == 422, r.text
        fields = _bad_fields(r.json())
        assert "/items/0/image" in fields, r.text  # the job's own checks ran, not only its schema
        assert ("/webhook_url" not in fields) == accepted, r.text


def _settings(**changes) -> Settings:
    return Settings(api_keys=API_KEYS, webhook_secret=SECRET, webhook_allowed_hosts=["127.0.0.1"],
                    **changes)


@pytest.mark.parametrize(("url", "https_only", "http_too"), POLICY)
def test_the_worker_and_the_api_share_the_function(url, https_only, http_too):
    for allow_http, accepted in ((False, https_only), (True, http_too)):
        settings = _settings(webhook_allow_http=allow_http, webhook_allow_private=True)
        for resolve in (False, True):  # the API's call, the worker's call
            if accepted:
                checked = check_webhook_url(url, settings, resolve=resolve)
                assert checked.addresses == (("127.0.0.1",) if resolve else ())
            else:
                with pytest.raises(ReferenceError):
                    check_webhook_url(url, settings, resolve=resolve)


def test_the_worker_alone_checks_the_address(listener):
    url = f"https://127.0.0.1:{listener.getsockname()[1]}/hook"
    settings = _settings(webhook_allow_private=False)
    assert check_webhook_url(url, settings, resolve=False).host == "127.0.0.1"  # the API's view
    with pytest.raises(ReferenceError, match="private or local"):
        check_webhook_url(url, settings, resolve=True)


@pytest.fixture(scope="module")
def strict_worker(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    """A worker with the default rule (https only), fed jobs through the store directly."""
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("strict-worker"), db=15,
                    bucket="t-webhooks-strict", tiles_per_face=2, items_in_flight=1,
                    extra_env={"WEBHOOK_ALLOW_HTTP": "false"}) as made:
        yield made


def test_the_worker_refuses_http_before_connecting(strict_worker, scene, listener):
    # A job whose http URL was accepted under another setting (or written past the API): the
    # worker applies the rule as it stands at delivery, and never connects.
    url = f"http://127.0.0.1:{listener.getsockname()[1]}/hook"
    job_id = strict_worker.submit([spec_for(strict_worker.upload(encode(scene.image)), scene)],
                                  webhook_url=url)
    assert strict_worker.wait(job_id).state == State.succeeded
    deadline = time.monotonic() + 60
    while f"webhook of job {job_id} not sent" not in strict_worker.worker.log:
        assert time.monotonic() < deadline, strict_worker.worker.log[-3000:]
        time.sleep(0.2)
    assert "https URLs only" in strict_worker.worker.log
    with pytest.raises(BlockingIOError):
        listener.accept()


# -- the secret --------------------------------------------------------------------------------------

def test_the_signer_reproduces_the_specifications_test_vector():
    # Published with the specification and its reference libraries.
    headers = signed_headers("msg_p5jXN8AQM9LWM0D4loKWxJek", b'{"test": 2432232314}',
                             key=signing_key("whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw"),
                             at=datetime.fromtimestamp(1614265330.9, tz=UTC))
    assert headers == {"webhook-id": "msg_p5jXN8AQM9LWM0D4loKWxJek", "webhook-timestamp": "1614265330",
                       "webhook-signature": "v1,g0hM9SsE+OTPJTGt/tmIKtSyZlE3uFJELVlNIOLJ1OE="}


@pytest.mark.parametrize(("secret", "key"), [
    (SECRET, KEY),
    (SECRET.rstrip("="), KEY),  # unpadded base64, as the reference libraries accept it
    ("webhook-secret-for-tests", b"webhook-secret-for-tests"),  # plain: its UTF-8 bytes
    ("k-Zx_9-ünï✓", "k-Zx_9-ünï✓".encode()),
    ("whsec_" + base64.b64encode(b"plain bytes").decode(), b"plain bytes"),
])
def test_either_form_of_secret_signs_with_its_documented_key(secret, key):
    now = datetime.now(UTC)
    body = b'{"id": "x", "state": "succeeded"}'
    headers = signed_headers("job.finished.x", body, key=signing_key(secret), at=now)
    assert headers["webhook-signature"] == _spec_signature(key, headers, body)
    # What the README tells a receiver to pass: a whsec_ secret as it is, any other as bytes.
    verifier = Webhook(secret if secret.startswith("whsec_") else secret.encode())
    assert verifier.verify(body, headers) == json.loads(body)
    assert Webhook("whsec_" + base64.b64encode(key).decode()).verify(body, headers) == json.loads(body)


@pytest.mark.parametrize("secret", ["", "whsec_", "whsec_not base64!", "whsec_abc$def", "whsec_a"])
def test_a_malformed_secret_stops_the_start_without_showing_it(secret):
    with pytest.raises(ValidationError, match="webhook secret") as caught:
        Settings(api_keys=API_KEYS, webhook_secret=secret)
    if len(secret) > len("whsec_"):
        assert secret not in str(caught.value)


def test_payload_bytes_are_what_was_signed(delivered):
    # The body is compact JSON in UTF-8, signed as sent: a receiver must verify the raw bytes,
    # not a re-serialisation (which would differ, e.g. in spacing).
    _, delivery = delivered
    reserialised = json.dumps(json.loads(delivery.body)).encode()
    assert reserialised != delivery.body
    with pytest.raises(WebhookVerificationError):
        Webhook(SECRET).verify(reserialised, delivery.headers)


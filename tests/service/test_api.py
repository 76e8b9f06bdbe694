"""The HTTP API in process (TestClient), against the real Redis and SeaweedFS of the fixtures.

Nobody consumes the Celery queue here: a submitted job stays queued, and the tests read the
queued message itself from Redis.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import socket
import struct
import time
import uuid
import warnings
import zlib
from collections.abc import Callable, Iterator

import anyio
import httpx
import pytest
import redis
from prism_common.metrics import record_task_duration
from prism_common.queue import TASK_RUN_JOB
from prism_common.records import ItemResult, State
from prism_common.settings import Settings, get_settings
from prometheus_client.parser import text_string_to_metric_families
from pydantic import SecretStr

from prism_api.main import create_app
from prism_api.routes.health import PROBE_TIMEOUT_S
from prism_cli.stack import start_api

from .conftest import API_KEYS
from .servers import free_port

with warnings.catch_warnings():
    # Starlette now prefers the httpx2 fork for its TestClient; httpx is what the project has.
    warnings.filterwarnings("ignore", "Using `httpx` with `starlette.testclient`")
    from fastapi.testclient import TestClient

ACME = {"X-API-Key": API_KEYS["acme"]}
GLOBEX = {"X-API-Key": API_KEYS["globex"]}
POINTS = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]

MakeClient = Callable[..., TestClient]


@pytest.fixture
def make_client(settings, objects) -> Iterator[MakeClient]:
    """A TestClient on a fresh app whose settings are the fixture's, with `changes` applied."""
    clients: list[TestClient] = []

    def make(lifespan: bool = True, **changes) -> TestClient:
        app = create_app()
        app_settings = settings.model_copy(update=changes)
        app.dependency_overrides[get_settings] = lambda: app_settings
        client = TestClient(app)
        if lifespan:
            client.__enter__()
            clients.append(client)
        return client

    yield make
    for client in clients:
        client.__exit__(None, None, None)


@pytest.fixture
def client(make_client) -> TestClient:
    return make_client()


@pytest.fixture
def broker(settings) -> redis.Redis:
    return redis.Redis.from_url(settings.redis_url, decode_responses=True)


def photo(size: int = 0, width: int = 256, height: int = 128) -> bytes:
    """A black PNG of width x height px, padded after its end to `size` bytes with random ones
    (readers stop at IEND; the upload's probe reads the header): uploads must be photos."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    rows = zlib.compress((b"\x00" * (1 + 3 * width)) * height, 9)
    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", rows) + chunk(b"IEND", b""))
    assert size == 0 or size >= len(data), (size, len(data))
    return data + os.urandom(max(0, size - len(data)))


def upload(client: TestClient, data: bytes | None = None, name: str = "box.png",
           headers: dict = ACME) -> str:
    r = client.post("/v1/uploads", files={"file": (name, photo() if data is None else data)}, headers=headers)
    assert r.status_code in (200, 201), r.text  # 200: the same content again
    return r.json()["reference"]


def item(image: str, **extra) -> dict:
    return {"image": image, "points": POINTS, **extra}


def submit(client: TestClient, items: list[dict], headers: dict = ACME, **extra) -> httpx.Response:
    return client.post("/v1/jobs", json={"items": items, **extra}, headers=headers)


def fresh_tenant(make_client: MakeClient, settings: Settings, **changes) -> tuple[TestClient, dict]:
    """A client and headers of a tenant of the test's own, whose job list starts empty."""
    key = f"key-{uuid.uuid4().hex}"
    keys = {**settings.api_keys, f"t-{uuid.uuid4().hex[:8]}": SecretStr(key)}
    return make_client(api_keys=keys, **changes), {"X-API-Key": key}


# -- authentication and tenants ---------------------------------------------------------------
# A fixed unknown id (real ones are uuid4's): the test ids must be the same in every
# pytest-xdist process.
V1_CALLS = [("GET", "/v1/jobs"), ("POST", "/v1/jobs"), ("GET", f"/v1/jobs/{'5' * 32}"),
            ("POST", f"/v1/jobs/{'6' * 32}/cancel"), ("POST", "/v1/uploads")]


@pytest.mark.parametrize(("method", "path"), V1_CALLS)
@pytest.mark.parametrize("headers", [{}, {"X-API-Key": ""}, {"X-API-Key": "nope"},
                                     {"X-API-Key": API_KEYS["acme"] + "x"},
                                     {"X-API-Key": API_KEYS["acme"][:-1]}, {"X-API-Key": "ключ".encode()},
                                     {"Authorization": f"Bearer {API_KEYS['acme']}"}])
def test_every_v1_call_needs_a_valid_key(client, method, path, headers):
    body = {"json": {"items": [item("upload:" + "0" * 32)]}} if path == "/v1/jobs" else {}
    r = client.request(method, path, headers=headers, **body)
    assert r.status_code == 401, r.text
    assert r.headers["WWW-Authenticate"] == "ApiKey"
    assert isinstance(r.json()["detail"], str)
    assert API_KEYS["acme"][:-1] not in r.text


def test_the_key_is_checked_before_the_body(client):
    r = client.post("/v1/jobs", json={"items": [], "unknown": 1})
    assert r.status_code == 401


def test_another_tenants_job_is_answered_like_an_unknown_one(client):
    job_id = submit(client, [item(upload(client))]).json()["id"]
    assert client.get(f"/v1/jobs/{job_id}", headers=ACME).status_code == 200
    for path in (f"/v1/jobs/{job_id}", f"/v1/jobs/{job_id}/cancel"):
        method = "POST" if path.endswith("cancel") else "GET"
        theirs = client.request(method, path, headers=GLOBEX)
        unknown = client.request(method, path.replace(job_id, uuid.uuid4().hex), headers=GLOBEX)
        assert theirs.status_code == unknown.status_code == 404
        assert theirs.json()["detail"].replace(job_id, "ID") == unknown.json()["detail"].replace(
            unknown.url.path.split("/")[3], "ID")
    assert job_id not in [j["id"] for j in client.get("/v1/jobs", headers=GLOBEX).json()["jobs"]]
    assert client.get(f"/v1/jobs/{job_id}", headers=ACME).json()["state"] == "queued"


@pytest.mark.parametrize("job_id", ["..%2F..%2Fetc", "not-hex", "A" * 32, "0" * 500],
                         ids=["dotdot", "not-hex", "upper", "long"])
def test_malformed_job_ids_are_unknown(client, job_id):
    assert client.get(f"/v1/jobs/{job_id}", headers=ACME).status_code == 404


# -- uploads ----------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "stored_name"), [
    ("box.jpg", "box.jpg"), ("../../etc/passwd", "passwd"), ("C:\\photos\\side.png", "side.png"),
    ("", "upload")], ids=["plain", "path", "windows-path", "no-name"])  # ids: bucket-safe
def test_upload_round_trip(client, store, objects, name, stored_name):
    data = photo(300_000)
    r = client.post("/v1/uploads", files={"file": (name, data, "image/jpeg")}, headers=ACME)
    assert r.status_code == 201, r.text
    body = r.json()
    assert body == {"id": body["id"], "reference": f"upload:{body['id']}", "size": len(data),
                    "name": stored_name, "probe": {
                        "kind": "image", "format": "PNG", "width": 256, "height": 128, "frame_count": None,
                        "fps": None, "codec": None, "error": None},
                    "sha256": hashlib.sha256(data).hexdigest()}
    record = store.get_upload(body["id"])
    assert record["tenant"] == "acme" and int(record["size"]) == len(data)
    assert record["key"].startswith("uploads/") and "acme" not in record["key"]
    assert objects.get_bytes(record["key"]) == data


@pytest.mark.parametrize(("size", "code"), [(1000, 201), (1001, 413), (5_000_000, 413)])
def test_upload_size_limit(make_client, objects, size, code):
    # 1001 bytes is caught while counting, 5 MB already by its Content-Length.
    client = make_client(upload_max_bytes=1000)
    r = client.post("/v1/uploads", files={"file": ("a.png", photo(size, 16, 8))}, headers=ACME)
    assert r.status_code == code, r.text
    assert len(objects.list_keys("uploads/")) == (code == 201)
    if code == 413:
        assert "1000 bytes" in r.json()["detail"]


@pytest.mark.parametrize("limit", [100_000, 9 * 2**20])  # one PUT; multipart (over 8 MiB)
def test_upload_over_the_limit_is_refused_while_streaming(settings, objects, limit):
    app = create_app()
    app_settings = settings.model_copy(update={"upload_max_bytes": limit})
    app.dependency_overrides[get_settings] = lambda: app_settings
    chunk, total_chunks, sent = 2**16, 1000, 0  # 64 MiB offered, no Content-Length (chunked)

    async def body():
        nonlocal sent
        yield (b'--b0undary\r\nContent-Disposition: form-data; name="file"; filename="big.bin"\r\n'
               b"Content-Type: application/octet-stream\r\n\r\n")
        for _ in range(total_chunks):
            sent += 1
            yield b"\x00" * chunk
        yield b"\r\n--b0undary--\r\n"

    async def post() -> httpx.Response:
        # httpx's ASGI transport hands the body to the app chunk by chunk, as the app asks.
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app),
                                     base_url="http://testserver") as http:
            return await http.post("/v1/uploads", content=body(), headers={
                **ACME, "Content-Type": "multipart/form-data; boundary=b0undary"})

    r = anyio.run(post)
    assert r.status_code == 413, r.text
    assert sent <= limit // chunk + 2  # read just past the limit, not the other ~60 MiB
    assert objects.list_keys("uploads/") == []
    assert not objects.client.list_multipart_uploads(Bucket=objects.bucket).get("Uploads")


def test_client_leaving_mid_upload_stores_nothing(settings, objects):
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    messages = iter([
        {"type": "http.request", "more_body": True,
         "body": b'--b0undary\r\nContent-Disposition: form-data; name="file"; filename="a"\r\n\r\n'},
        {"type": "http.request", "body": b"\x00" * 2**16, "more_body": True},
        {"type": "http.disconnect"}])
    sent: list[dict] = []

    async def receive() -> dict:
        return next(messages)

    async def send(message: dict) -> None:
        sent.append(message)

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
             "scheme": "http", "path": "/v1/uploads", "raw_path": b"/v1/uploads", "root_path": "",
             "query_string": b"", "client": ("127.0.0.1", 50000), "server": ("127.0.0.1", 80),
             "headers": [(b"x-api-key", API_KEYS["acme"].encode()),
                         (b"content-type", b"multipart/form-data; boundary=b0undary")]}
    anyio.run(app, scope, receive, send)
    assert sent[0]["status"] == 400
    assert objects.list_keys("uploads/") == []


def test_upload_over_the_limit_under_uvicorn(settings, objects, tmp_path):
    # The real server: the client is told 413 and stops sending long before its 64 MiB are out.
    env = {"PRISM_API_KEYS": json.dumps(API_KEYS), "PRISM_WEBHOOK_SECRET": "s",
           "PRISM_REDIS_URL": settings.redis_url, "PRISM_S3_ENDPOINT_URL": settings.s3_endpoint_url,
           "PRISM_S3_BUCKET": settings.s3_bucket,
           "PRISM_S3_ACCESS_KEY_ID": settings.s3_access_key_id.get_secret_value(),
           "PRISM_S3_SECRET_ACCESS_KEY": settings.s3_secret_access_key.get_secret_value(),
           "PRISM_UPLOAD_MAX_BYTES": str(2**20)}
    api = start_api(tmp_path / "api", env)
    sent = 0

    def body() -> Iterator[bytes]:
        nonlocal sent
        yield b'--b0undary\r\nContent-Disposition: form-data; name="file"; filename="big"\r\n\r\n'
        for _ in range(1000):
            sent += 1
            yield b"\x00" * 2**16
        yield b"\r\n--b0undary--\r\n"

    try:
        r = httpx.post(f"http://127.0.0.1:{api.port}/v1/uploads", content=body(), timeout=30,
                       headers={**ACME, "Content-Type": "multipart/form-data; boundary=b0undary"})
        assert r.status_code == 413, r.text
        assert sent < 500
        assert objects.list_keys("uploads/") == []
    finally:
        api.stop()


def _refused_before_the_body(port: int, path: str, content_type: str, framing: str, key: str | None
                             ) -> tuple[int, dict[str, str], int, float]:
    """Send a request's headers over a real socket, no body: (status, headers) of the answer
    that comes back before any of the body, the bytes of a 256 MiB body the server then took
    before it refused more, and the seconds until the server closed the connection."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    try:
        auth = f"X-API-Key: {key}\r\n" if key is not None else ""
        sock.sendall(f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: {content_type}\r\n"
                     f"{framing}\r\n{auth}\r\n".encode())
        answer = b""
        while b"\r\n\r\n" not in answer:
            got = sock.recv(65536)
            assert got, answer
            answer += got
        head, body = answer.split(b"\r\n\r\n", 1)
        lines = head.decode().split("\r\n")
        headers = {k.strip().lower(): v.strip() for k, v in (line.split(":", 1) for line in lines[1:])}
        while len(body) < int(headers["content-length"]):
            body += sock.recv(65536)
        started = time.monotonic()
        sock.settimeout(3)  # under uvicorn's 5 s keep-alive: a connection kept open times out here
        try:
            closed = sock.recv(1) == b""
        except TimeoutError:
            closed = False
        closed_s = time.monotonic() - started if closed else float("inf")
        sent, chunk = 0, b"\x00" * 2**16
        try:
            while sent < 256 * 2**20:
                sock.sendall(chunk)
                sent += len(chunk)
        except (BrokenPipeError, ConnectionResetError, TimeoutError):
            pass
        return int(lines[0].split()[1]), headers, sent, closed_s
    finally:
        sock.close()


def test_a_body_sent_without_a_valid_key_is_not_read(settings, objects, tmp_path):
    """Issue 37: POST /v1/uploads and /v1/stations without a valid key answered 401 but read the
    body to its end (3 GB tried, ~1 GB/s taken in, the connection left open). Now the 401 comes
    from the headers, before any of the body is sent, and the connection is closed: the server
    takes no more than what the sockets' buffers hold of a 256 MiB body."""
    env = {"PRISM_API_KEYS": json.dumps(API_KEYS), "PRISM_WEBHOOK_SECRET": "s",
           "PRISM_REDIS_URL": settings.redis_url, "PRISM_S3_ENDPOINT_URL": settings.s3_endpoint_url,
           "PRISM_S3_BUCKET": settings.s3_bucket,
           "PRISM_S3_ACCESS_KEY_ID": settings.s3_access_key_id.get_secret_value(),
           "PRISM_S3_SECRET_ACCESS_KEY": settings.s3_secret_access_key.get_secret_value()}
    api = start_api(tmp_path / "api", env)
    multipart = "multipart/form-data; boundary=b0undary"
    chunked = "Transfer-Encoding: chunked"
    # Declared sizes under each route's own cap (over it, 413 comes first, unread, as before).
    try:
        for path, content_type, framing, key in [
                ("/v1/uploads", multipart, f"Content-Length: {3 * 2**30}", None),
                ("/v1/uploads", multipart, chunked, "wrong"),
                ("/v1/stations", multipart, f"Content-Length: {60 * 2**20}", "wrong"),
                ("/v1/stations", multipart, chunked, None),
                ("/v1/stations", "application/json", f"Content-Length: {15 * 2**20}", None)]:
            case = (path, content_type, framing, key)
            code, headers, sent, closed_s = _refused_before_the_body(api.port, *case)
            print(case, code, f"{sent / 2**20:.2f} MiB taken, closed after {closed_s:.3f} s")
            assert code == 401 and headers.get("connection") == "close", (case, code, headers)
            assert closed_s < 2, (case, closed_s)  # closed at once, not kept alive
            assert sent < 2 * 2**20, (case, sent)  # the server stopped reading
        # A valid key's upload is read as ever.
        r = httpx.post(f"http://127.0.0.1:{api.port}/v1/uploads", headers=ACME,
                       files={"file": ("a.png", photo())}, timeout=30)
        assert r.status_code in (200, 201), r.text
    finally:
        api.stop()


@pytest.mark.parametrize("request_kwargs", [
    {"json": {"file": "abc"}}, {"data": {"other": "field"}, "files": {"other": ("a", b"x")}},
    {"files": {"file": ("empty.jpg", b"")}},
    {"content": b"--xx\r\nContent-Disposition: form-data; name=\"file\"\r\n\r\nabc",
     "headers": {"Content-Type": "multipart/form-data; boundary=xx"}},
    {"content": b"garbage", "headers": {"Content-Type": "multipart/form-data; boundary=xx"}},
])
def test_bad_uploads_are_422(client, objects, request_kwargs):
    headers = {**ACME, **request_kwargs.pop("headers", {})}
    r = client.post("/v1/uploads", headers=headers, **request_kwargs)
    assert r.status_code == 422, r.text
    assert objects.list_keys("uploads/") == []


# -- submitting jobs --------------------------------------------------------------------------
def _queued_message(broker: redis.Redis) -> dict:
    # kombu's Redis transport LPUSHes each message onto the list named after the queue.
    return json.loads(broker.lindex("scans", 0))


def test_submit_queues_the_job_and_get_returns_it(make_client, store, broker):
    client = make_client(max_pixels=1_000_000)
    ref = upload(client)
    depth = broker.llen("scans")
    r = submit(client, [item(ref), item(ref, side_image=ref, max_pixels=500)],
               client_reference="order-7", webhook_url="https://127.0.0.1/hook")
    assert r.status_code == 202, r.text
    job = r.json()
    assert r.headers["Location"] == f"/v1/jobs/{job['id']}"
    assert broker.llen("scans") == depth + 1
    message = _queued_message(broker)
    assert message["headers"]["task"] == TASK_RUN_JOB and job["id"] in message["headers"]["argsrepr"]
    got = client.get(r.headers["Location"], headers=ACME)
    assert got.status_code == 200 and got.json() == job
    assert job["state"] == "queued" and job["progress"] == 0 and job["client_reference"] == "order-7"
    assert job["webhook_url"] == "https://127.0.0.1/hook" and job["error"] is None
    assert [i["index"] for i in job["items"]] == [0, 1]
    assert job["items"][0] == {"index": 0, "state": "queued", "error": None, "result": None,
                               "downloads": {}, "frames": []}
    # The service's pixel limit caps what an item asks for; a lower limit of its own stays.
    record = store.get(job["id"])
    assert record.tenant == "acme" and record.items[1].spec.side_image == ref
    assert [i.spec.max_pixels for i in record.items] == [1_000_000, 500]


def test_location_behind_a_proxy(make_client):
    client = make_client(public_base_url="https://scans.example.com/")
    r = submit(client, [item(upload(client))])
    assert r.headers["Location"] == f"https://scans.example.com/v1/jobs/{r.json()['id']}"


@pytest.mark.parametrize(("reference", "reason"), [
    ("s3://private-bucket/photos/a.jpg", "bucket 'private-bucket' is not one the service may read"),
    ("upload:" + "ab" * 16, "no upload"),
    ("http://127.0.0.1/a.jpg", "is not a reference"),
    ("https://images.example.com/a.jpg", "not on the fetch allow-list"),
    ("https://user:pw@127.0.0.1/a.jpg", "credentials"),
    ("s3://inputs/../secret", "unsafe object key"),
    ("just garbage", "is not a reference"),
], ids=["s3-bucket", "unknown-upload", "http", "host", "credentials", "s3-dotdot", "garbage"])
@pytest.mark.parametrize("field", ["image", "side_image"])
def test_bad_references_name_the_item(make_client, broker, reference, reason, field):
    client = make_client(readable_buckets=["inputs"], fetch_allowed_hosts=["127.0.0.1"])
    good = upload(client)
    depth = broker.llen("scans")
    r = submit(client, [item(good), {**item(good), field: reference}])
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == f"/items/1/{field}"
    assert error["detail"].startswith(f"item 1 {field}: ") and reason in error["detail"]
    assert broker.llen("scans") == depth


def test_another_tenants_upload_is_no_upload(client):
    theirs = upload(client, headers=GLOBEX)
    r = submit(client, [item(theirs)])
    assert r.status_code == 422
    assert r.json()["errors"][0]["detail"] == f"item 0 image: no upload {theirs.split(':')[1]!r}"
    assert submit(client, [item(theirs)], headers=GLOBEX).status_code == 202


def test_every_bad_item_is_reported(client):
    r = submit(client, [item("nope"), item(upload(client)), item("s3://private/a", side_image="x")])
    assert [e["pointer"] for e in r.json()["errors"]] == [
        "/items/0/image", "/items/2/image", "/items/2/side_image"]


@pytest.mark.parametrize("reference", ["s3://inputs/line-3/photo.jpg", "https://CDN.example.com/a.jpg"],
                         ids=["s3", "https"])
def test_allowed_references_are_accepted(make_client, reference):
    client = make_client(readable_buckets=["inputs"], fetch_allowed_hosts=["cdn.example.com"])
    assert submit(client, [item(reference)]).status_code == 202


@pytest.mark.parametrize(("url", "allow_private", "ok"), [
    ("https://127.0.0.1/hook", False, True), ("https://127.0.0.1:8443/hook?x=1", False, True),
    ("http://127.0.0.1:8080/hook", True, True), ("http://127.0.0.1/hook", False, False),
    ("https://hooks.example.com/hook", True, False), ("https://u:p@127.0.0.1/hook", True, False),
    ("ftp://127.0.0.1/hook", True, False), ("https://127.0.0.1:99999/hook", True, False),
    ("not a url", True, False),
], ids=["https", "https-port", "http-private", "http", "host", "credentials", "ftp", "bad-port",
        "garbage"])
def test_webhook_urls(make_client, url, allow_private, ok):
    # The full rule, http included, is tested in test_webhooks.py (API and worker alike).
    client = make_client(webhook_allow_private=allow_private, webhook_allow_http=allow_private)
    r = submit(client, [item(upload(client))], webhook_url=url)
    assert r.status_code == (202 if ok else 422), r.text
    if not ok:
        assert r.json()["errors"][0]["pointer"] == "/webhook_url"


GOOD = {"image": "upload:" + "0" * 32, "points": POINTS}


BAD_BODIES = {
    "no-items": b'{"items": [], "client_reference": null}',
    "unknown-field": json.dumps({"items": [GOOD], "colour": "red"}).encode(),
    "unknown-item-field": json.dumps({"items": [{**GOOD, "colour": "red"}]}).encode(),
    "three-points": json.dumps({"items": [{**GOOD, "points": POINTS[:3]}]}).encode(),
    "pinhole-no-focal": json.dumps(
        {"items": [{**GOOD, "scale": {"kind": "pinhole", "distance_mm": 500}}]}).encode(),
    "tolerance": json.dumps({"items": [{**GOOD, "tolerance": -1}]}).encode(),
    "format": json.dumps({"items": [{**GOOD, "formats": ["obj"]}]}).encode(),
    "long-reference": json.dumps({"items": [GOOD], "client_reference": "x" * 201}).encode(),
    "items-not-list": json.dumps({"items": GOOD}).encode(),
    "nan-principal": json.dumps({"items": [{**GOOD, "principal_point": [float("nan"), 1.0]}]}).encode(),
    "inf-tolerance": json.dumps({"items": [{**GOOD, "tolerance": float("inf")}]}).encode(),
    "nan-point": json.dumps({"items": [{**GOOD, "points": [[float("nan"), 1], *POINTS[1:]]}]}).encode(),
    "truncated": b'{"items": [', "array": b"[]", "empty": b"", "not-utf8": b"\xff\xfe",
    "string": b'"items"',
}


NOT_JSON = ("truncated", "not-utf8")  # nothing to point into: 400, as the OpenAPI says


@pytest.mark.parametrize("body", BAD_BODIES.values(), ids=BAD_BODIES.keys())
def test_bad_bodies_are_readable_problems(client, body):
    r = client.post("/v1/jobs", content=body, headers={**ACME, "Content-Type": "application/json"})
    not_json = body in [BAD_BODIES[k] for k in NOT_JSON]
    assert r.status_code == (400 if not_json else 422), r.text
    assert r.headers["content-type"] == "application/problem+json"
    problem = r.json()
    assert problem["type"] == ("https://prismcloud.dev/problems/bad-request" if not_json
                               else "https://prismcloud.dev/problems/validation")
    assert problem["instance"] == "/v1/jobs" and isinstance(problem["detail"], str)
    if not_json:
        assert "not valid JSON" in problem["detail"] and "errors" not in problem
    else:
        errors = problem["errors"]
        assert errors and all(isinstance(e["detail"], str) and e["detail"] for e in errors)
        assert all(set(e) == {"pointer", "detail"} and (e["pointer"] == "" or e["pointer"].startswith("/"))
                   for e in errors)


def test_too_many_items(make_client):
    client = make_client(max_items_per_job=2)
    ref = upload(client)
    assert submit(client, [item(ref)] * 2).status_code == 202
    r = submit(client, [item(ref)] * 3)
    assert r.status_code == 422 and "at most 2 items" in r.json()["errors"][0]["detail"]


# -- idempotency ------------------------------------------------------------------------------
def test_idempotency_key(client, broker):
    items = [item(upload(client))]
    key = {**ACME, "Idempotency-Key": f"order-{uuid.uuid4().hex}"}
    depth = broker.llen("scans")
    first = client.post("/v1/jobs", json={"items": items}, headers=key)
    again = client.post("/v1/jobs", json={"items": items}, headers=key)
    assert first.status_code == again.status_code == 202
    assert first.json()["id"] == again.json()["id"]
    assert again.headers["Location"].endswith(first.json()["id"])
    assert broker.llen("scans") == depth + 1  # the repeat sent nothing
    other = client.post("/v1/jobs", json={"items": items * 2}, headers=key)
    assert other.status_code == 409 and "Idempotency-Key" in other.json()["detail"]
    # The same key from another tenant is another key.
    assert client.post("/v1/jobs", json={"items": [item(upload(client, headers=GLOBEX))]},
                       headers={**key, **GLOBEX}).status_code == 202
    one, two = (client.post("/v1/jobs", json={"items": items}, headers=ACME) for _ in range(2))
    assert one.status_code == two.status_code == 202 and one.json()["id"] != two.json()["id"]
    assert broker.llen("scans") == depth + 4


# -- cancelling -------------------------------------------------------------------------------
def test_cancel(client, store):
    job_id = submit(client, [item(upload(client))]).json()["id"]
    first = client.post(f"/v1/jobs/{job_id}/cancel", headers=ACME)
    assert first.status_code == 200, first.text
    # Nothing had finished: progress counts finished work only, and the item reads cancelled.
    assert first.json()["state"] == "cancelled" and first.json()["progress"] == 0
    assert [i["state"] for i in first.json()["items"]] == ["cancelled"]
    assert first.json()["finished_at"] is not None
    again = client.post(f"/v1/jobs/{job_id}/cancel", headers=ACME)
    assert again.status_code == 200 and again.json() == first.json()
    assert store.state(job_id) == State.cancelled


@pytest.mark.parametrize("final", [State.succeeded, State.completed_with_failures, State.failed])
def test_cancel_after_the_end_conflicts(client, store, final):
    job_id = submit(client, [item(upload(client))]).json()["id"]
    store.transition(job_id, State.running)
    store.transition(job_id, final)
    r = client.post(f"/v1/jobs/{job_id}/cancel", headers=ACME)
    assert r.status_code == 409 and r.json() == {
        "type": "https://prismcloud.dev/problems/conflict", "title": "Conflict with the resource's state",
        "status": 409, "detail": f"job is already {final.value}", "instance": f"/v1/jobs/{job_id}/cancel"}
    assert store.state(job_id) == final


def test_cancel_a_running_job(client, store):
    job_id = submit(client, [item(upload(client))]).json()["id"]
    store.transition(job_id, State.running)
    r = client.post(f"/v1/jobs/{job_id}/cancel", headers=ACME)
    assert r.status_code == 200 and r.json()["state"] == "cancelled"
    assert r.json()["started_at"] is not None


# -- listing ----------------------------------------------------------------------------------
def test_list_pages_newest_first_with_state_filter(make_client, settings):
    client, headers = fresh_tenant(make_client, settings)
    ref = upload(client, headers=headers)
    ids = [submit(client, [item(ref)], headers=headers).json()["id"] for _ in range(5)]
    for job_id in ids[1:3]:
        client.post(f"/v1/jobs/{job_id}/cancel", headers=headers)

    def pages(query: str) -> list[list[str]]:
        out, cursor = [], None
        while True:
            params = f"{query}&cursor={cursor}" if cursor else query
            r = client.get(f"/v1/jobs?{params}", headers=headers)
            assert r.status_code == 200, r.text
            out.append([j["id"] for j in r.json()["jobs"]])
            if (cursor := r.json()["next_cursor"]) is None:
                return out

    newest_first = ids[::-1]
    assert pages("limit=2") == [newest_first[:2], newest_first[2:4], newest_first[4:]]
    assert pages("limit=5") == [newest_first]
    assert pages("limit=200") == [newest_first]
    assert pages("state=cancelled&limit=1") == [[ids[2]], [ids[1]]]
    assert pages("state=queued") == [[ids[4], ids[3], ids[0]]]
    assert pages("state=succeeded") == [[]]
    listed = client.get("/v1/jobs", headers=headers).json()["jobs"]
    assert listed[0] == client.get(f"/v1/jobs/{ids[4]}", headers=headers).json()


@pytest.mark.parametrize("query", [
    "state=done", "limit=0", "limit=201", "limit=ten", "cursor=garbage!",
    "cursor=" + base64.urlsafe_b64encode(b"nan").decode(), "cursor=" + "A" * 101,
    "cursor=" + base64.urlsafe_b64encode(b"inf").decode()],
    ids=["state", "limit-0", "limit-201", "limit-text", "cursor", "cursor-nan", "cursor-long",
         "cursor-inf"])
def test_bad_list_parameters_are_422(client, query):
    r = client.get(f"/v1/jobs?{query}", headers=ACME)
    assert r.status_code == 422, r.text
    assert "parameter" in r.json()["errors"][0], r.text


# -- results and downloads --------------------------------------------------------------------
def test_results_and_presigned_downloads(client, store, objects):
    job_id = submit(client, [item(upload(client)), item(upload(client))]).json()["id"]
    record = store.get(job_id)
    done = record.items[0].model_copy(update={
        "state": State.succeeded,
        "result": ItemResult(points=1234, dimensions={"width": 120.0, "height": 80.0,
                                                      "depth": 60.0, "unit": "mm"},
                             point_loss=0.01, warnings=["low contrast"]),
        "outputs": {"csv": f"jobs/{job_id}/0/cloud.csv", "report": f"jobs/{job_id}/0/report.json"}})
    store.put_item(job_id, done)
    store.put_item(job_id, record.items[1].model_copy(update={"state": State.failed,
                                                              "error": "no edges found"}))
    objects.put_bytes(f"jobs/{job_id}/0/cloud.csv", b"1,2,3\n")
    objects.put_bytes(f"jobs/{job_id}/0/report.json", b'{"points": 1234}')
    store.transition(job_id, State.succeeded)

    job = client.get(f"/v1/jobs/{job_id}", headers=ACME).json()
    assert job["state"] == "succeeded" and job["progress"] == 100
    first, second = job["items"]
    assert first["result"] == {"points": 1234, "dimensions": {"width": 120.0, "height": 80.0,
                                                              "depth": 60.0, "unit": "mm"},
                               "point_loss": 0.01, "warnings": ["low contrast"], "summary": None,
                               "uncertainty": None, "focal_px": None, "focal_source": None,
                               "fit_rms_px": None, "side_face": None, "quality": None,
                               "points_source": None, "points_confidence": None, "given_dimension": None,
                               "reference_points": None, "joint": None, "station": None}
    assert set(first["downloads"]) == {"csv", "report"}  # only what the item has
    csv = httpx.get(first["downloads"]["csv"])
    assert csv.status_code == 200 and csv.content == b"1,2,3\n"
    assert "cloud.csv" in csv.headers["Content-Disposition"]
    assert httpx.get(first["downloads"]["report"]).json() == {"points": 1234}
    assert second == {"index": 1, "state": "failed", "error": "no edges found", "result": None,
                      "downloads": {}, "frames": []}
    # Polling again reuses the URLs (presigning is slow) while they are fresh.
    assert client.get(f"/v1/jobs/{job_id}", headers=ACME).json()["items"][0] == first
    # Nobody else can fetch the job to get at the URLs.
    assert client.get(f"/v1/jobs/{job_id}", headers=GLOBEX).status_code == 404


def test_download_links_are_signed_for_the_public_endpoint(make_client, settings, store, objects):
    # The API talks to the store at 127.0.0.1; clients are told another name for it.
    public = settings.s3_endpoint_url.replace("127.0.0.1", "localhost")
    client = make_client(s3_public_endpoint_url=public)
    job_id = submit(client, [item(upload(client))]).json()["id"]
    record = store.get(job_id)
    store.put_item(job_id, record.items[0].model_copy(update={
        "state": State.succeeded, "result": ItemResult(points=1, point_loss=0.0, dimensions={
            "width": 1.0, "height": 1.0, "depth": 1.0, "unit": "mm"}),
        "outputs": {"csv": f"jobs/{job_id}/0/cloud.csv"}}))
    objects.put_bytes(f"jobs/{job_id}/0/cloud.csv", b"4,5,6\n")
    store.transition(job_id, State.succeeded)
    url = client.get(f"/v1/jobs/{job_id}", headers=ACME).json()["items"][0]["downloads"]["csv"]
    assert url.startswith(public + "/"), url
    got = httpx.get(url)  # the signature holds for the host the client used
    assert got.status_code == 200 and got.content == b"4,5,6\n"


@pytest.mark.parametrize("query", ["item_offset=1&item_limit=2", "item_offset=3", "item_limit=0",
                                   "item_offset=9&item_limit=1"])
def test_a_page_of_items_is_that_slice_of_the_whole_job(client, store, query):
    ref = upload(client)
    job_id = submit(client, [item(ref) for _ in range(5)]).json()["id"]
    record = store.get(job_id)
    store.put_item(job_id, record.items[2].model_copy(update={"state": State.failed, "error": "e"}))
    whole = client.get(f"/v1/jobs/{job_id}", headers=ACME).json()
    got = client.get(f"/v1/jobs/{job_id}?{query}", headers=ACME).json()
    params = dict(pair.split("=") for pair in query.split("&"))
    offset, limit = int(params.get("item_offset", 0)), int(params.get("item_limit", 10**9))
    assert got["items"] == whole["items"][offset:offset + limit]
    assert {k: v for k, v in got.items() if k != "items"} == {k: v for k, v in whole.items()
                                                                if k != "items"}
    assert got["item_count"] == whole["item_count"] == 5
    # Paged or not, another tenant's job is not there.
    assert client.get(f"/v1/jobs/{job_id}?{query}", headers=GLOBEX).status_code == 404


def test_a_job_renews_the_uploads_it_reads(client, broker):
    ref = upload(client)
    upload_id = ref.removeprefix("upload:")
    broker.zadd("prism:uploads", {upload_id: 1.0})  # as if made in 1970
    submit(client, [item(ref)])
    assert broker.zscore("prism:uploads", upload_id) > time.time() - 60  # counted from now


def test_a_listing_can_leave_the_items_out(client):
    job_id = submit(client, [item(upload(client)) for _ in range(3)]).json()["id"]
    full = client.get("/v1/jobs?limit=200", headers=ACME).json()["jobs"]
    bare = client.get("/v1/jobs?limit=200&items=false", headers=ACME).json()["jobs"]
    assert [j["id"] for j in bare] == [j["id"] for j in full]
    mine = next(j for j in bare if j["id"] == job_id)
    assert mine["items"] == [] and mine["item_count"] == 3
    assert [{**j, "items": []} for j in full] == bare


@pytest.mark.parametrize("query", ["item_offset=-1", "item_limit=-1", "item_limit=10001",
                                   "item_offset=x"])
def test_bad_item_pages_are_422(client, query):
    job_id = submit(client, [item(upload(client))]).json()["id"]
    r = client.get(f"/v1/jobs/{job_id}?{query}", headers=ACME)
    assert r.status_code == 422, r.text


# -- probes, metrics, OpenAPI -----------------------------------------------------------------
def test_probes_need_no_key(client):
    assert client.get("/healthz").json() == {"status": "ok"}
    r = client.get("/readyz")
    assert r.status_code == 200 and r.json() == {"redis": "ok", "object_store": "ok"}


@pytest.mark.parametrize("down", ["redis", "object_store"])
def test_readyz_names_what_is_down_quickly(make_client, settings, down):
    dead = f"127.0.0.1:{free_port()}"  # nothing listens there
    changes = ({"redis_url": f"redis://{dead}/0"} if down == "redis"
               else {"s3_endpoint_url": f"http://{dead}"})
    client = make_client(lifespan=False, **changes)  # startup would fail on a dead object store
    # Within the probes' own cap (PROBE_TIMEOUT_S each way, at most twice that), and a second for
    # the request: boto3's or redis's retries would take longer on every try. The best of three
    # tries counts, so a scheduling stall on a loaded machine (the answer takes 0.1-0.2 s idle)
    # does not fail it; a slow probe is slow every time.
    bound = 2 * PROBE_TIMEOUT_S + 1
    took: list[float] = []
    while len(took) < 3 and (not took or min(took) >= bound):
        started = time.monotonic()
        r = client.get("/readyz")
        took.append(time.monotonic() - started)
        assert r.status_code == 503
    assert min(took) < bound, took
    assert r.status_code == 503
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["type"] == "https://prismcloud.dev/problems/backend-unavailable"
    assert r.json()["checks"] == {"redis": "ok", "object_store": "ok", down: "down"}


def test_a_dead_redis_is_503_not_500(make_client):
    client = make_client(redis_url=f"redis://127.0.0.1:{free_port()}/0")
    r = client.get("/v1/jobs", headers=ACME)
    assert r.status_code == 503 and "unavailable" in r.json()["detail"]


def test_metrics(client, broker):
    submit(client, [item(upload(client))])
    record_task_duration(broker, "prism.scan_tile", 0.3)
    record_task_duration(broker, "prism.scan_tile", 7.0)
    r = client.get("/metrics")
    assert r.status_code == 200 and r.headers["Content-Type"].startswith("text/plain")
    samples = {(s.name, tuple(sorted(s.labels.items()))): s.value
               for family in text_string_to_metric_families(r.text) for s in family.samples}
    assert samples[("prism_jobs", (("state", "queued"),))] >= 1
    assert {("prism_jobs", (("state", s.value),)) for s in State} <= set(samples)
    assert samples[("prism_queue_depth", (("queue", "scans"),))] == broker.llen("scans") >= 1
    tile = {le: samples[("prism_task_duration_seconds_bucket", (("le", le), ("task", "prism.scan_tile")))]
            for le in ("0.25", "0.5", "10.0", "+Inf")}
    count = samples[("prism_task_duration_seconds_count", (("task", "prism.scan_tile"),))]
    assert tile["0.5"] - tile["0.25"] >= 1 and tile["10.0"] - tile["0.5"] >= 1
    assert tile["+Inf"] == count >= 2


def test_openapi(client):
    spec = client.get("/openapi.json").json()
    assert {"/v1/jobs", "/v1/jobs/{job_id}", "/v1/jobs/{job_id}/cancel", "/v1/uploads"} <= set(
        spec["paths"])
    assert {"JobCreate", "JobPublic", "ItemPublic", "JobList", "UploadPublic", "ScanSpec"} <= set(
        spec["components"]["schemas"])
    [scheme] = spec["components"]["securitySchemes"].values()
    assert scheme == {"type": "apiKey", "in": "header", "name": "X-API-Key",
                      "description": scheme.get("description")}
    assert "multipart/form-data" in spec["paths"]["/v1/uploads"]["post"]["requestBody"]["content"]


def test_the_api_does_not_load_the_engine():
    # The API validates specs with pydantic alone; numpy/OpenCV belong to the workers.
    import subprocess
    import sys

    code = ("import sys, prism_api.main; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'cv2', 'prism_worker'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(("indices", "ok"), [([[0, 1, 2], [3, 4]], True), ([[0, 1, 2], [3, 4, 5]], False),
                                             ([list(range(6))], False)])
def test_frames_named_over_the_job_cap_are_refused_at_submit(make_client, indices, ok):
    client = make_client(max_frames_per_job=5)
    ref = upload(client, b"RIFF....AVI ", name="clip.avi")
    r = submit(client, [item(ref, frames={"indices": i}) for i in indices])
    assert r.status_code == (202 if ok else 422), r.text
    if not ok:
        named = sum(map(len, indices))
        assert r.json()["errors"][0]["detail"].endswith(
            f"the job's videos name {named} frames, over the cap of 5 frames per job")
    else:
        assert [it["frames"] for it in r.json()["items"]] == [[], []]  # none measured yet


@pytest.mark.parametrize("chunked", [True, False])
@pytest.mark.parametrize("headers", [{}, ACME], ids=["no key", "key"])
def test_a_job_body_over_the_cap_is_refused_while_it_arrives(settings, chunked, headers):
    # FastAPI reads a JSON body before the key is checked: the cap holds for strangers too.
    app = create_app()
    app_settings = settings.model_copy(update={"request_max_bytes": 100_000})
    app.dependency_overrides[get_settings] = lambda: app_settings
    chunk, sent = b" " * 2**14, 0  # 16 MiB of JSON whitespace offered

    async def body():
        nonlocal sent
        yield b'{"items": []'
        for _ in range(1024):
            sent += 1
            yield chunk
        yield b"}"

    async def post() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app),
                                     base_url="http://testserver") as http:
            if chunked:
                return await http.post("/v1/jobs", content=body(), headers=headers)
            return await http.post("/v1/jobs", content=b"[" + b" " * 200_000 + b"]",
                                   headers={**headers, "Content-Type": "application/json"})

    r = anyio.run(post)
    assert r.status_code == 413, r.text
    assert r.json()["detail"] == ("the request body is larger than 100000 bytes "
                                  "(PRISM_REQUEST_MAX_BYTES)")
    assert sent <= 100_000 // len(chunk) + 2  # read just past the cap


@pytest.mark.parametrize("root_path", ["", "/prism"])
def test_uploads_are_not_held_to_the_request_cap(settings, objects, root_path):
    # Uploads have their own, larger limit, also when the app runs under a root path.
    app = create_app()
    app_settings = settings.model_copy(update={"request_max_bytes": 1000})
    app.dependency_overrides[get_settings] = lambda: app_settings
    with TestClient(app, root_path=root_path) as client:
        r = client.post(f"{root_path}/v1/uploads", files={"file": ("big.png", photo(50_000))},
                        headers=ACME)
        assert r.status_code in (200, 201), r.text  # 200: the same content again
        assert client.post(f"{root_path}/v1/jobs", content=b" " * 2000, headers=ACME).status_code == 413


def test_a_job_body_under_the_cap_is_read_as_usual(settings, objects):
    # 2,000 items of ~330 bytes: about 0.7 MB of JSON under the default cap of 16 MiB.
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    with TestClient(app) as client:
        ref = client.post("/v1/uploads", files={"file": ("a.png", photo())}, headers=ACME)
        item = {"image": ref.json()["reference"], "points": [[10, 10], [110, 12], [108, 80],
                                                              [150, 6], [200, 8]]}
        r = client.post("/v1/jobs", json={"items": [item] * 2000}, headers=ACME)
    assert r.status_code == 202, r.text
    assert len(r.json()["items"]) == 2000

"""Access, in process against the real Redis and SeaweedFS: every /v1 route (read from the
OpenAPI document, so a new one cannot slip past) with no key, a wrong key and another tenant's
key; presigned URLs that expire; keys compared in constant time and never logged nor stored.
"""

from __future__ import annotations

import logging
import time
import uuid
import warnings
from datetime import UTC, datetime
from urllib.parse import parse_qs, urlsplit

import httpx
import pytest
import redis
from prism_common.records import State
from prism_common.settings import get_settings
from pydantic import SecretStr

from prism_api import deps
from prism_api.main import create_app

from .conftest import API_KEYS
from .test_api import photo

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "Using `httpx` with `starlette.testclient`")
    from fastapi.testclient import TestClient

ACME, GLOBEX = {"X-API-Key": API_KEYS["acme"]}, {"X-API-Key": API_KEYS["globex"]}
POINTS = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]
WRONG_KEYS = [{}, {"X-API-Key": ""}, {"X-API-Key": "wrong"}, {"X-API-Key": API_KEYS["acme"] + " "},
              {"X-API-Key": API_KEYS["acme"].upper()}, {"x-api-key": API_KEYS["acme"][:-1]}]
# What another tenant's key gets on each route when aimed at acme's job (or acme's upload).
ROUTES = {("POST", "/v1/uploads"): 201, ("POST", "/v1/jobs"): 422, ("GET", "/v1/jobs"): 200,
          ("GET", "/v1/jobs/{job_id}"): 404, ("POST", "/v1/jobs/{job_id}/cancel"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/preview.ply"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/frames/{frame}/preview.ply"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/overlay.jpg"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/frames/{frame}/overlay.jpg"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/overlay.png"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/frames/{frame}/overlay.png"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/box.glb"): 404,
          ("GET", "/v1/jobs/{job_id}/items/{index}/tracked_points.json"): 404,
          ("GET", "/v1/jobs/{job_id}/results.csv"): 404, ("GET", "/v1/jobs/{job_id}/results.json"): 404,
          ("GET", "/v1/uploads/{upload_id}/video"): 404,
          ("GET", "/v1/uploads/{upload_id}/frames/{frame}.png"): 404,
          ("GET", "/v1/uploads/{upload_id}/points"): 404,
          ("POST", "/v1/stations"): 422, ("GET", "/v1/stations"): 200,
          ("GET", "/v1/stations/{station_id}"): 404, ("GET", "/v1/stations/{station_id}/station.json"): 404,
          ("DELETE", "/v1/stations/{station_id}"): 404,
          ("GET", "/v1/stations/{station_id}/verifications"): 404,
          ("POST", "/v1/stations/{station_id}/verifications"): 404}
# A station.json with no plate: its board, camera and plane are all the API checks.
STATION = {"board": {"type": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 7, "squares_y": 5,
                     "square_mm": 30, "marker_mm": 22},
           "camera": {"fx": 1400, "fy": 1400, "cx": 639.5, "cy": 511.5, "image_width": 1280,
                      "image_height": 1024},
           "plane": {"rvec": [0.0, 0.0, 0.0], "tvec": [-100.0, -75.0, 600.0], "rms_px": 0.1, "corners": 24}}


@pytest.fixture
def make(settings, objects):
    clients = []

    def make(**changes) -> TestClient:
        app = create_app()
        app_settings = settings.model_copy(update=changes)
        app.dependency_overrides[get_settings] = lambda: app_settings
        clients.append(client := TestClient(app).__enter__())
        return client

    yield make
    for client in clients:
        client.__exit__(None, None, None)


def _acme_job(client: TestClient) -> tuple[str, str]:
    r = client.post("/v1/uploads", files={"file": ("a.png", photo())}, headers=ACME)
    ref = r.json()["reference"]
    job = client.post("/v1/jobs", json={"items": [{"image": ref, "points": POINTS}]}, headers=ACME)
    return job.json()["id"], ref


def test_every_route_that_reads_or_changes_a_job_is_guarded(make, figures):
    client = make()
    # The published paths: FastAPI includes routers lazily, so app.routes no longer lists them.
    routes = {(method.upper(), path) for path, ops in create_app().openapi()["paths"].items()
              if path.startswith("/v1") for method in ops}
    assert routes == set(ROUTES), "a /v1 route was added: give it its row in ROUTES"
    job_id, ref = _acme_job(client)
    made = client.post("/v1/stations", json=STATION, headers=ACME)
    assert made.status_code == 201, made.text
    station_id = made.json()["id"]
    for (method, path), theirs in ROUTES.items():
        upload_id = ref.removeprefix("upload:")
        url = path.format(job_id=job_id, index=0, frame=0, upload_id=upload_id, station_id=station_id)
        kwargs = ({"json": {"items": [{"image": ref, "points": POINTS}]}} if path == "/v1/jobs" and
                  method == "POST" else {"files": {"file": ("b.png", photo())}}
                  if path == "/v1/uploads" else {"json": {}} if path == "/v1/stations" and method == "POST"
                  else {})
        for headers in WRONG_KEYS:
            r = client.request(method, url, headers=headers, **kwargs)
            assert r.status_code == 401, (method, url, headers, r.text)
            figures["inputs tried"] += 1
        r = client.request(method, url, headers=GLOBEX, **kwargs)
        assert r.status_code == theirs, (method, url, r.text)
        if theirs == 404:  # the answer an unknown id gets: nothing of the job, upload or station
            unknown = (f"no upload {upload_id!r}" if "{upload_id}" in path else
                       f"no station {station_id!r}" if "{station_id}" in path else f"no job {job_id!r}")
            assert r.json() == {"type": "https://prismcloud.dev/problems/not-found",
                                "title": "No such resource", "status": 404, "detail": unknown,
                                "instance": url}, r.text
        else:
            assert job_id not in r.text and station_id not in r.text, r.text
        if method == "GET" and path == "/v1/jobs":
            assert job_id not in [j["id"] for j in r.json()["jobs"]]
    assert client.get(f"/v1/jobs/{job_id}", headers=ACME).json()["state"] == "queued"  # untouched
    assert client.get(f"/v1/stations/{station_id}", headers=ACME).status_code == 200  # not deleted


def _download_in_time(client: TestClient, job_id: str) -> tuple[str, float, httpx.Response]:
    """A poll's csv link, its end (its signing time, X-Amz-Date in whole seconds, + X-Amz-Expires)
    and its download. A link is valid for presign_ttl_s from its signing: a loaded machine can
    spend the few seconds a test's short ttl leaves between the poll and the store's check, so a
    refusal answered only after the link's own end asks for a fresh link (a refusal answered
    before it is the failure it is)."""
    for _ in range(10):
        url = client.get(f"/v1/jobs/{job_id}", headers=ACME).json()["items"][0]["downloads"]["csv"]
        query = parse_qs(urlsplit(url).query)
        signed = datetime.strptime(query["X-Amz-Date"][0], "%Y%m%dT%H%M%SZ").replace(tzinfo=UTC)
        expiry = signed.timestamp() + int(query["X-Amz-Expires"][0])
        answer = httpx.get(url)
        if answer.status_code == 200 or time.time() < expiry:
            return url, expiry, answer
    raise AssertionError("every link ran out before its download was answered")


def test_presigned_urls_expire(make, store, objects):
    client = make(presign_ttl_s=5)
    job_id, _ = _acme_job(client)
    key = f"jobs/{job_id}/items/0/cloud.csv"
    objects.put_bytes(key, b"1,2,3\n")
    record = store.get(job_id)
    store.put_item(job_id, record.items[0].model_copy(update={"state": State.succeeded,
                                                              "outputs": {"csv": key}}))
    url, expiry, answer = _download_in_time(client, job_id)
    assert answer.status_code == 200 and answer.content == b"1,2,3\n"
    assert parse_qs(urlsplit(url).query)["X-Amz-Expires"] == ["5"]
    time.sleep(max(0.0, expiry + 1.2 - time.time()))  # past the URL's own end, whatever the load
    assert httpx.get(url).status_code == 403  # the store refuses it once its time is up
    fresh, _, answer = _download_in_time(client, job_id)
    assert fresh != url and answer.status_code == 200  # a poll hands out a new one


def test_keys_are_compared_in_constant_time(make, settings, monkeypatch):
    # Every configured key is compared with hmac.compare_digest on every call that presents a
    # key, whichever (if any) matches: no early exit that would time how many keys, or which,
    # came first. A call without a key has nothing to compare.
    many = {**settings.api_keys, **{f"t{i}": SecretStr(f"key-{uuid.uuid4().hex}") for i in range(5)}}
    client = make(api_keys=many)
    calls: list[bytes] = []
    real = deps.hmac.compare_digest

    def counting(a, b):
        calls.append(b)
        return real(a, b)

    monkeypatch.setattr(deps.hmac, "compare_digest", counting)
    for headers in (ACME, GLOBEX, {"X-API-Key": many["t4"].get_secret_value()}, {"X-API-Key": "wrong"}):
        calls.clear()
        client.get("/v1/jobs", headers=headers)
        assert len(calls) == len(many), headers
    calls.clear()
    assert client.get("/v1/jobs").status_code == 401 and calls == []


def test_keys_are_never_logged_nor_stored(make, caplog, settings, figures):
    caplog.set_level(logging.DEBUG)
    tenant_key = f"key-{uuid.uuid4().hex}"
    client = make(api_keys={**settings.api_keys, "logtest": SecretStr(tenant_key)}, rate_limit_per_minute=3)
    answers = [client.get("/v1/jobs", headers={"X-API-Key": tenant_key}).status_code for _ in range(5)]
    assert 429 in answers  # the limit's refusal path ran too
    for headers in ({"X-API-Key": tenant_key + "x"}, ACME):
        client.get("/v1/jobs/" + "0" * 32, headers=headers)
        client.post("/v1/jobs", content=b"{bad", headers={**headers, "Content-Type": "application/json"})
    secrets = [tenant_key, *API_KEYS.values()]
    logged = "\n".join(f"{r.getMessage()} {r.args}" for r in caplog.records)
    assert not any(s in logged for s in secrets)
    r = redis.Redis.from_url(settings.redis_url, decode_responses=True)
    for name in r.scan_iter("prism:*", count=1000):  # neither in a key's name nor in its value
        assert not any(s in name for s in secrets), name
        if r.type(name) == "string":
            assert not any(s in (r.get(name) or "") for s in secrets), name

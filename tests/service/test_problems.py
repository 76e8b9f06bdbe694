"""Every error the API sends is an RFC 9457 problem document (application/problem+json), in
process on the real Redis and SeaweedFS of the fixtures, and the OpenAPI document says so."""

# ruff: noqa: F811 - `client` and `make_client` are test_api's fixtures, imported to be used as such
from __future__ import annotations

import uuid

import pytest
from fastapi import APIRouter
from prism_common.settings import get_settings
from pydantic import SecretStr

from prism_api.main import create_app
from prism_api.problems import BASE, KINDS

from .servers import free_port
from .test_api import ACME, TestClient, client, item, make_client, upload  # noqa: F401 (fixtures)

MEMBERS = {"type", "title", "status", "detail", "instance"}


def problem(r, status: int, kind: str) -> dict:
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == "application/problem+json", r.headers
    body = r.json()
    assert set(body) >= MEMBERS and body["status"] == status, body
    assert body["type"] == BASE + kind and body["title"] == KINDS[kind].title, body
    assert isinstance(body["detail"], str) and body["detail"] and "\n" not in body["detail"]
    return body


@pytest.mark.parametrize(("method", "path", "kwargs", "status", "kind"), [
    ("GET", "/v1/jobs", {}, 401, "unauthorized"),
    ("GET", f"/v1/jobs/{'a' * 32}", {"headers": ACME}, 404, "not-found"),
    ("GET", "/v1/nothing-here", {"headers": ACME}, 404, "not-found"),
    ("DELETE", "/v1/jobs", {"headers": ACME}, 405, "method-not-allowed"),
    ("POST", "/v1/jobs", {"headers": {**ACME, "Content-Type": "application/json"}, "content": b'{"items": ['},
     400, "bad-request"),
    ("POST", "/v1/jobs", {"headers": {**ACME, "Content-Length": "99999999"}, "content": b"{}"}, 413,
     "body-too-large"),
    ("POST", "/v1/uploads", {"headers": ACME, "files": {"file": ("a.txt", b"hello\n")}}, 415,
     "unsupported-media-type"),
], ids=["401", "404-job", "404-route", "405", "400-json", "413", "415"])
def test_errors_are_problems(client, method, path, kwargs, status, kind):
    body = problem(client.request(method, path, **kwargs), status, kind)
    assert body["instance"] == path


def test_a_405_names_every_method_the_path_answers(client):
    """Allow lists every method of the path, as the OpenAPI document has them, not only the first
    route's (Starlette's router answered PUT /v1/jobs with "Allow: POST", GET /v1/jobs being
    another route); GET routes of plain Starlette also answer HEAD."""
    paths = create_app().openapi()["paths"]
    values = {"job_id": "a" * 32, "station_id": "b" * 32, "upload_id": "c" * 32, "index": 0, "frame": 0}
    assert {"/v1/jobs", "/v1/stations", "/v1/stations/{station_id}"} <= set(paths)
    for template, operations in paths.items():
        documented = {m.upper() for m in operations}
        refused = next(m for m in ("PUT", "PATCH", "DELETE", "POST") if m not in documented)
        path = template.format(**values)
        r = client.request(refused, path, headers=ACME)
        problem(r, 405, "method-not-allowed")
        allowed = [m.strip() for m in r.headers["Allow"].split(",")]
        assert set(allowed) - {"HEAD"} == documented and len(allowed) == len(set(allowed)), (path, allowed)
        assert "HEAD" not in allowed or "GET" in allowed, (path, allowed)
    for path, both in (("/v1/jobs", {"GET", "POST"}), ("/v1/stations", {"GET", "POST"}),
                       (f"/v1/stations/{'b' * 32}", {"GET", "DELETE"})):
        assert set(client.put(path, headers=ACME).headers["Allow"].split(", ")) == both


def test_headers_are_kept(make_client):
    r = make_client().get("/v1/jobs")
    assert problem(r, 401, "unauthorized") and r.headers["WWW-Authenticate"] == "ApiKey"
    secret = f"k-{uuid.uuid4().hex}"
    limited = make_client(rate_limit_per_minute=1, api_keys={"solo": SecretStr(secret)})
    key = {"X-API-Key": secret}
    assert limited.get("/v1/jobs", headers=key).status_code == 200
    r = limited.get("/v1/jobs", headers=key)
    assert problem(r, 429, "rate-limited") and int(r.headers["Retry-After"]) >= 1


@pytest.mark.parametrize(("change", "pointer"), [
    ({"points": {"p1": [1, 1], "p2": [9, 1], "p3": "x", "p4": [1, 1], "p5": [1, 1]}}, "/items/0/points/p3"),
    ({"points": [[1, 1], [9, 1], "x", [1, 1], [1, 1]]}, "/items/0/points/2"),
    ({"scale": {"kind": "pinhole"}, "focal_px": 900}, "/items/0/scale/distance_mm"),  # no "pinhole" step
    # The tag "edge" is also a key of a known edge: the pointer still reaches the bad value.
    ({"scale": {"kind": "edge", "edge": "width", "length_mm": -1}}, "/items/0/scale/length_mm"),
    ({"scale": {"kind": "edge", "edge": "width"}}, "/items/0/scale/length_mm"),
    ({"scale": {"kind": "edge", "edge": "diagonal", "length_mm": 9}}, "/items/0/scale/edge"),
    ({"tolerance": -1}, "/items/0/tolerance"),
    ({"colour": "red"}, "/items/0/colour"),
])
def test_validation_points_into_the_body(client, change, pointer):
    r = client.post("/v1/jobs", json={"items": [{"image": "upload:" + "0" * 32, **change}]}, headers=ACME)
    body = problem(r, 422, "validation")
    assert pointer in [e["pointer"] for e in body["errors"]], body
    assert body["detail"].startswith(body["errors"][0]["pointer"]), body


MM = {"kind": "mm_per_px", "front": 0.2}
CAMERA = {"fx": 900.0, "fy": 900.0, "cx": 128.0, "cy": 64.0, "image_width": 256, "image_height": 128}


@pytest.mark.parametrize(("change", "pointer", "quoted"), [
    ({"scale": {"kind": "edge", "edge": "width", "length_mm": 1e300}}, "/items/0/scale/length_mm",
     "1e+300 mm"),
    ({"scale": {"kind": "edge", "edge": "depth", "length_mm": 1e-9}}, "/items/0/scale/length_mm",
     "1e-09 mm"),
    ({"scale": {"kind": "mm_per_px", "front": 5e3}}, "/items/0/scale/front", "5000 mm/px"),
    ({"scale": {"kind": "mm_per_px", "front": 0.2, "side": 1e-7}}, "/items/0/scale/side", "1e-07 mm/px"),
    ({"scale": {"kind": "pinhole", "distance_mm": 2e6}, "focal_px": 900}, "/items/0/scale/distance_mm",
     "2e+06 mm"),
    ({"scale": {"kind": "pinhole", "distance_mm": 500, "side_distance_mm": 1e300}, "focal_px": 900},
     "/items/0/scale/side_distance_mm", "1e+300 mm"),
    ({"scale": {"kind": "pinhole", "distance_mm": 500}, "focal_px": 1e300}, "/items/0/focal_px", "1e+300 px"),
    ({"camera": {**CAMERA, "fy": 1e300}}, "/items/0/camera/fy", "1e+300 px"),
    ({"scale": MM, "nominal": [120, 80, 1e300], "tolerance_mm": 1}, "/items/0/nominal/2", "1e+300 mm"),
    ({"scale": MM, "nominal": [120, 80, 60], "tolerance_mm": 1e300}, "/items/0/tolerance_mm", "1e+300 mm"),
    ({"scale": MM, "nominal": [120, 80, 60], "tolerance_mm": [1, 2e6, 1]}, "/items/0/tolerance_mm/1",
     "2e+06 mm"),
    ({"scale": MM, "spacing_mm": 1e300}, "/items/0/spacing_mm", "1e+300 mm"),
], ids=["length-huge", "length-tiny", "mm-per-px", "mm-per-px-side", "distance", "side-distance",
        "focal", "camera-focal", "nominal", "tolerance", "tolerance-each", "spacing"])
def test_every_scale_and_length_is_bounded_at_submit(client, change, pointer, quoted):
    # Issue 21: length_mm 1e300 was accepted (202) and its item failed when polled ("points hold
    # 746250 non-finite values"). Refused at submit, the problem points at the value and quotes it.
    r = client.post("/v1/jobs", json={"items": [item(upload(client), **change)]}, headers=ACME)
    body = problem(r, 422, "validation")
    # (A value of a union, as tolerance_mm's one value or three, has an error per branch.)
    found = [e["detail"] for e in body["errors"] if e["pointer"] == pointer]
    assert found and quoted in found[0] and "out of range" in found[0], body


@pytest.mark.parametrize("change", [
    {"scale": {"kind": "edge", "edge": "width", "length_mm": 1e6}},
    {"scale": {"kind": "edge", "edge": "width", "length_mm": 1e-3}},
    {"scale": {"kind": "mm_per_px", "front": 1e3, "side": 1e-6}},
    {"scale": {"kind": "pinhole", "distance_mm": 1e6}, "focal_px": 1e6},
    {"scale": MM, "nominal": [1e6, 1e-3, 60], "tolerance_mm": [0, 1e6, 1], "spacing_mm": 1e6},
], ids=["length-max", "length-min", "mm-per-px-bounds", "distance-focal-max", "quality-bounds"])
def test_the_bounds_themselves_are_accepted(client, change):
    r = client.post("/v1/jobs", json={"items": [item(upload(client), **change)]}, headers=ACME)
    assert r.status_code == 202, r.text


def test_parameters_and_headers_are_named(client):
    body = problem(client.get("/v1/jobs?limit=0", headers=ACME), 422, "validation")
    assert body["errors"] == [{"parameter": "limit", "detail": body["errors"][0]["detail"]}]
    r = client.post("/v1/jobs", json={"items": [item(upload(client))]},
                    headers={**ACME, "Idempotency-Key": "k" * 201})
    assert problem(r, 422, "validation")["errors"][0]["header"] == "idempotency-key"


def test_backend_down_is_503_with_retry_after(make_client):
    r = make_client(redis_url=f"redis://127.0.0.1:{free_port()}/0").get("/v1/jobs", headers=ACME)
    assert problem(r, 503, "backend-unavailable") and r.headers["Retry-After"].isdigit()


def test_at_capacity_is_its_own_kind(make_client, client):
    ref = upload(client)
    full = make_client(queue_max_depth=1)
    full.post("/v1/jobs", json={"items": [item(ref)]}, headers=ACME)  # nobody consumes: one waits
    r = full.post("/v1/jobs", json={"items": [item(ref)]}, headers=ACME)
    assert problem(r, 503, "at-capacity") and r.headers["Retry-After"].isdigit()


def test_unhandled_errors_leak_nothing(settings, objects):
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    boom = APIRouter()

    @boom.get("/boom")
    def _boom() -> None:
        raise RuntimeError("secret internals at /srv/prism/x.py")

    app.include_router(boom)
    with TestClient(app, raise_server_exceptions=False) as client:
        r = client.get("/boom")
    body = problem(r, 500, "internal-error")
    assert "secret" not in r.text and "RuntimeError" not in r.text and body["instance"] == "/boom"


def test_openapi_declares_a_problem_for_every_error():
    document = create_app().openapi()
    schemas = document["components"]["schemas"]
    assert "Problem" in schemas and "HTTPValidationError" not in schemas
    errors = 0
    for path, operations in document["paths"].items():
        for method, op in operations.items():
            codes = {int(c) for c in op["responses"] if c.isdigit()}
            assert 500 in codes, (method, path)
            for code, response in op["responses"].items():
                if code.isdigit() and int(code) >= 400:
                    errors += 1
                    assert response["content"] == {"application/problem+json": {
                        "schema": {"$ref": "#/components/schemas/Problem"}}}, (method, path, code)
    post_jobs = document["paths"]["/v1/jobs"]["post"]["responses"]
    assert {"400", "401", "409", "413", "422", "429", "500", "503"} <= set(post_jobs)
    assert errors > 40

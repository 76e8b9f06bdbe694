"""Rough edges a newcomer hit with the HTTP API (issue 30), in process on the real Redis and
SeaweedFS of the fixtures: a JSON body sent as text/plain, a point no float holds, an upload
reference of the right form naming no upload, HEAD probes."""

# ruff: noqa: F811 - `client` is test_api's fixture, imported to be used as such
from __future__ import annotations

import json

from .test_api import ACME, client, make_client, photo  # noqa: F401 (fixtures)

POINTS = {"p1": [10, 10], "p2": [110, 12], "p3": [108, 80], "p4": [110, 12], "p5": [200, 8]}


def _ref(client) -> str:
    r = client.post("/v1/uploads", files={"file": ("p.png", photo())}, headers=ACME)
    assert r.status_code == 201, r.text
    return r.json()["reference"]


def test_json_sent_as_text_is_refused_naming_its_content_type(client):
    body = json.dumps({"items": [{"image": _ref(client), "points": POINTS}]})
    r = client.post("/v1/jobs", content=body, headers={**ACME, "Content-Type": "text/plain"})
    assert r.status_code == 415 and r.headers["content-type"] == "application/problem+json", r.text
    problem = r.json()
    assert problem["type"] == "https://prismcloud.dev/problems/unsupported-media-type"
    assert problem["detail"].startswith("the body is sent as Content-Type 'text/plain'"), problem
    assert "application/json" in problem["detail"] and "valid dictionary" not in r.text
    assert problem["errors"] == [{"header": "Content-Type", "detail": problem["detail"]}]
    untyped = client.post("/v1/jobs", content=body, headers=ACME)
    assert untyped.status_code == 415, untyped.text
    assert untyped.json()["detail"].startswith("the body is sent without a Content-Type"), untyped.text
    # Sent as JSON, the same body is taken.
    for kind in ("application/json", "application/json; charset=utf-8"):
        r = client.post("/v1/jobs", content=body, headers={**ACME, "Content-Type": kind})
        assert r.status_code == 202, (kind, r.text)
    assert "415" in client.get("/openapi.json").json()["paths"]["/v1/jobs"]["post"]["responses"]


def test_a_point_no_float_holds_is_pointed_at(client):
    ref = _ref(client)
    body = json.dumps({"items": [{"image": ref, "points": POINTS}]}).replace("[10, 10]", "[1e400, 10]")
    r = client.post("/v1/jobs", content=body, headers={**ACME, "Content-Type": "application/json"})
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/points/p1/0" and "finite" in error["detail"], error


def test_other_non_finite_numbers_are_pointed_at_too(client):
    ref = _ref(client)
    body = json.dumps({"items": [{"image": ref, "points": POINTS, "principal_point": [5, 1e400]}]})
    r = client.post("/v1/jobs", content=body, headers={**ACME, "Content-Type": "application/json"})
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/principal_point/1" and "finite" in error["detail"], error


def test_an_upload_reference_says_what_is_wrong_with_it(client):
    def refused(image: str) -> dict:
        r = client.post("/v1/jobs", json={"items": [{"image": image, "points": POINTS}]}, headers=ACME)
        assert r.status_code == 422, r.text
        [error] = r.json()["errors"]
        assert error["pointer"] == "/items/0/image", error
        return error
    # The id's form is wrong: said so, and what an id is; not "use upload:ID", which it did.
    detail = refused("upload:0000")["detail"]
    assert detail.startswith("item 0 image: 'upload:0000' is not an upload id: an upload's id is the 32 "
                             "lowercase hex digits"), detail
    assert "use upload:ID" not in detail
    # The form is right, there is no such upload.
    assert refused("upload:" + "0" * 32)["detail"] == f"item 0 image: no upload {'0' * 32!r}"


def test_monitors_probe_with_head(client):
    for path, code in (("/healthz", 200), ("/readyz", 200), ("/", 307)):
        get = client.get(path, follow_redirects=False)
        head = client.head(path, follow_redirects=False)
        assert (get.status_code, head.status_code) == (code, code), (path, head.status_code, head.text)
        assert head.content == b"" and head.headers.get("location") == get.headers.get("location")
    paths = client.get("/openapi.json").json()["paths"]
    assert set(paths["/healthz"]) == {"get"} and set(paths["/readyz"]) == {"get"}  # HEAD undocumented

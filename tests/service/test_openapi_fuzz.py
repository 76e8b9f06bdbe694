"""Schemathesis against the published OpenAPI document, in process, on the real Redis and
SeaweedFS of the fixtures: whatever it sends (valid and invalid by the schema), no answer is a
5xx, and every answer matches what the document says (status, content type, body, headers).
"""

from __future__ import annotations

import hashlib
import warnings
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from prism_common.settings import get_settings
from schemathesis.checks import not_a_server_error
from schemathesis.core.failures import FailureGroup
from schemathesis.specs.openapi.checks import (
    allow_header_conformance,
    content_type_conformance,
    positive_data_acceptance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from prism_api.main import create_app

from .conftest import API_KEYS

CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance,
          response_schema_conformance, response_headers_conformance]


# The published document, read from the app itself; the calls go to that app in process, with
# the fixtures' settings (so the real Redis and SeaweedFS) put in by the autouse fixture below.
APP = create_app()
schema = schemathesis.openapi.from_dict(APP.openapi())
schema.app = APP


@pytest.fixture(autouse=True)
def _backends(settings, objects):
    APP.dependency_overrides[get_settings] = lambda: settings
    yield
    APP.dependency_overrides.clear()


@schema.parametrize()
@settings(max_examples=100, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
def test_no_5xx_and_every_answer_matches_the_schema(case, figures):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # the ASGI test client's own
        response = case.call(headers={"X-API-Key": API_KEYS["acme"]})
    figures["inputs tried"] += 1
    figures["5xx seen"] += response.status_code >= 500
    case.validate_response(response, checks=CHECKS)


# -- against a live API: schema-valid requests are accepted, or refused for a stated reason ------
# The API under uvicorn (as `prism serve` runs it) on the session's Redis and SeaweedFS, its
# OpenAPI document read from the server. Schemathesis' positive_data_acceptance and
# allow_header_conformance run on every answer; a schema-valid request refused with a 4xx other
# than a missing thing (404), a conflict (409) or the rate limit (429) must be one the operation
# documents, by status and by problem type (the response's `x-problem-types`). The ids in paths
# and the image references of generated jobs are swapped for real ones (generated hex names no
# upload), so generated requests reach the checks behind the lookups. Bounded by 12 examples an
# operation (derandomized), not by a clock: every operation is tried, however loaded the machine.


@pytest.fixture(scope="module")
def live_api(redis_server, s3_server, tmp_path_factory):
    from prism_cli.stack import start_api

    from .servers import service_env

    env = service_env(redis_server.port, s3_server.port, db=3, bucket="t-openapi-live",
                      RATE_LIMIT_PER_MINUTE="100000")
    proc = start_api(tmp_path_factory.mktemp("api"), env)
    base = f"http://127.0.0.1:{proc.port}"
    assert httpx.get(f"{base}/openapi.json", timeout=30).json() == LIVE.raw_schema
    yield base
    proc.stop()


@pytest.fixture(scope="module")
def real_ids(live_api) -> dict[str, list[str]]:
    """A photo, a 1x1 photo and a job of the tenant's: the ids generated paths are given."""
    from .test_api import photo

    key = {"X-API-Key": API_KEYS["acme"]}
    with httpx.Client(base_url=live_api, headers=key, timeout=30) as client:
        uploads = []
        for width, height in ((1280, 960), (1, 1)):
            r = client.post("/v1/uploads", files={"file": ("box.png", photo(width=width, height=height))})
            assert r.status_code in (200, 201), r.text
            uploads.append(r.json()["id"])
        clicks = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]
        r = client.post("/v1/jobs", json={"items": [{"image": f"upload:{uploads[0]}", "points": clicks}]})
        assert r.status_code == 202, r.text
    return {"upload_id": uploads, "job_id": [r.json()["id"]]}


# The document the live server serves is the app's own (checked by `live_api`'s callers below);
# schemathesis.pytest.from_fixture would read it from the server, but fails on this pytest.
LIVE = schemathesis.openapi.from_dict(create_app().openapi())
_TOLD = {401, 404, 409, 429}  # a missing key, a missing thing, a conflict, the rate limit: always said
_seen: dict[str, Any] = {"accepted jobs": 0}


def _with_real_ids(case: Any, ids: dict[str, list[str]]) -> None:
    pick = int(hashlib.sha256(repr(case.path_parameters).encode()).hexdigest(), 16)
    for name, real in ids.items():
        if case.path_parameters and name in case.path_parameters:
            case.path_parameters[name] = real[pick % len(real)]
    if case.method == "POST" and case.path == "/v1/jobs" and isinstance(case.body, dict):
        reference = f"upload:{ids['upload_id'][0]}"
        for item in case.body.get("items") or []:
            if not isinstance(item, dict):
                continue
            for name in ("image", "side_image"):
                if isinstance(item.get(name), str):
                    item[name] = reference
            for view in item.get("views") or []:
                if isinstance(view, dict) and isinstance(view.get("image"), str):
                    view["image"] = reference


def _documented(case: Any, response: Any) -> bool:
    """The operation lists the answer's status, and the problem's type among its types."""
    declared = case.operation.definition.raw.get("responses", {}).get(str(response.status_code))
    if declared is None:
        return False
    types = declared.get("x-problem-types", [])
    try:
        sent = response.json().get("type")
    except ValueError:
        return False
    return sent in types


@LIVE.parametrize()
@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
def test_schema_valid_requests_are_accepted_or_refused_as_documented(case, live_api, real_ids, figures):
    _with_real_ids(case, real_ids)
    response = case.call(base_url=live_api, headers={"X-API-Key": API_KEYS["acme"]}, timeout=30)
    figures["inputs tried"] += 1
    figures["5xx seen"] += response.status_code >= 500
    positive = case.meta is not None and case.meta.generation.mode.is_positive
    if positive and case.method == "POST" and case.path == "/v1/jobs" and response.status_code == 202:
        _seen["accepted jobs"] += 1
    case.validate_response(response, checks=[not_a_server_error, allow_header_conformance,
                                             status_code_conformance, content_type_conformance])
    if positive and response.status_code >= 400 and response.status_code not in _TOLD:
        try:
            case.validate_response(response, checks=[positive_data_acceptance])
        except (AssertionError, FailureGroup):
            assert _documented(case, response), (
                f"{case.method} {case.path}: a request the schema allows was refused with "
                f"{response.status_code} {response.text[:300]}, which the operation does not document")


def test_a_job_the_document_shows_is_accepted(live_api, real_ids):
    """The served document's example job (its upload swapped for a real one) is taken: 202. Runs
    after the fuzz above (pytest keeps a module's order), which counts its own accepted jobs."""
    document = httpx.get(f"{live_api}/openapi.json", timeout=30).json()
    example = document["components"]["schemas"]["JobCreate"]["examples"][0]
    for item in example["items"]:
        item["image"] = f"upload:{real_ids['upload_id'][0]}"
    r = httpx.post(f"{live_api}/v1/jobs", json=example, headers={"X-API-Key": API_KEYS["acme"]}, timeout=30)
    assert r.status_code == 202, r.text
    print(f"generated jobs accepted by the live fuzz: {_seen['accepted jobs']}")

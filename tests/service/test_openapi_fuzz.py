"""Schemathesis against the published OpenAPI document, in process, on the real Redis and
SeaweedFS of the fixtures: whatever it sends (valid and invalid by the schema), no answer is a
5xx, and every answer matches what the document says (status, content type, body, headers).
"""

from __future__ import annotations

import warnings

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from prism_common.settings import get_settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
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

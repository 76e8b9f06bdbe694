"""/docs (Swagger UI) and /redoc (ReDoc) work on a network without internet: in a real headless
Chromium, against the API under uvicorn, with every request that leaves loopback refused, the
pages list every operation of the OpenAPI document, load nothing from elsewhere, and break
neither their Content-Security-Policy nor any script. Chromium is the page tests' own (`browser`,
tests/web/conftest.py).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from urllib.parse import urlsplit

import httpx
import pytest
from playwright.sync_api import Route, expect
from service.servers import service_env

from prism_api.webapp import STATIC_DIR
from prism_cli.stack import ManagedProcess, start_api

LOOPBACK = {"127.0.0.1", "localhost", "[::1]", "::1"}


@pytest.fixture(scope="module")
def api(redis_server, s3_server, tmp_path_factory) -> Iterator[ManagedProcess]:
    if not (STATIC_DIR / "docs" / "swagger-ui-bundle.js").is_file():
        pytest.fail(f"the docs assets are not built in {STATIC_DIR / 'docs'}: run scripts/build-web")
    env = service_env(redis_server.port, s3_server.port, db=4, bucket="docs-offline")
    api = start_api(tmp_path_factory.mktemp("docs-api"), env)
    yield api
    api.stop()


def _operations(base: str) -> list[tuple[str, str]]:
    document = httpx.get(f"{base}/openapi.json", timeout=10).json()
    return [(method, path) for path, item in document["paths"].items() for method in item
            if method in ("get", "post", "put", "patch", "delete")]


# page -> (selector of one listed operation, how to read its path from the element)
PAGES = {
    # Swagger UI gives a deprecated operation's path a class of its own (the overlay.png routes)
    "/docs": ".opblock .opblock-summary-path, .opblock .opblock-summary-path__deprecated",
    "/redoc": "[data-section-id*='/operation/']",
}


@pytest.mark.parametrize("path", sorted(PAGES))
def test_docs_page_lists_every_operation_offline(api, browser, path):
    base = f"http://127.0.0.1:{api.port}"
    operations = _operations(base)
    assert len(operations) >= 8, operations
    context = browser.new_context(base_url=base)
    refused: list[str] = []
    problems: list[str] = []

    def only_loopback(route: Route) -> None:
        url = route.request.url
        if urlsplit(url).scheme in ("data", "blob") or urlsplit(url).hostname in LOOPBACK:
            route.continue_()
        else:
            refused.append(url)
            route.abort("internetdisconnected")

    context.route("**/*", only_loopback)
    page = context.new_page()
    page.on("pageerror", lambda exc: problems.append(f"uncaught: {exc}"))
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    try:
        response = page.goto(path)
        assert response is not None and response.status == 200
        assert "script-src 'self'" in response.headers["content-security-policy"]
        listed = page.locator(PAGES[path])
        listed.first.wait_for(timeout=30_000)
        # A locator's wait, not wait_for_function: a string predicate is evaluated in the page,
        # which its CSP (no 'unsafe-eval') refuses whenever the list is not complete at once.
        expect(listed).to_have_count(len(operations), timeout=30_000)
        shown = listed.count()
        text = page.locator("body").inner_text()
    finally:
        context.close()
    assert shown == len(operations), (shown, operations)
    for _, op_path in operations:  # every path of the document is on the page
        assert op_path in text, op_path
    assert refused == [], refused  # nothing was even asked of the outside
    assert problems == [], problems  # no CSP refusal, no script error


def test_docs_without_assets_say_how_to_build_them(tmp_path):
    from fastapi import FastAPI

    from prism_api.webapp import mount_docs

    with warnings.catch_warnings():
        # Starlette now prefers the httpx2 fork for its TestClient; httpx is what the project has.
        warnings.filterwarnings("ignore", "Using `httpx` with `starlette.testclient`")
        from fastapi.testclient import TestClient

    app = FastAPI(docs_url=None, redoc_url=None)
    mount_docs(app, tmp_path / "missing")
    with TestClient(app) as client:
        for path in ("/docs", "/redoc"):
            r = client.get(path)
            assert r.status_code == 404 and "scripts/setup" in r.text

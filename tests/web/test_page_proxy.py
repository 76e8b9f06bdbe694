"""The page behind a reverse proxy that puts the service under a path prefix (/prism/): its
assets, its login and its uploads all go through the prefix, nothing to the bare origin."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import httpx
import pytest
from page_driver import PageDriver, save_photo
from playwright.sync_api import expect

from prismsynth import Box, render_oblique_view

PREFIX = "/prism"
VIEWPORT = {"width": 1280, "height": 1000}
_HOP = {"connection", "keep-alive", "transfer-encoding", "content-length", "host"}


@pytest.fixture(scope="module")
def proxy(stack) -> Iterator[tuple[str, list[str]]]:
    """http://127.0.0.1:port with the API under PREFIX; yields it and the paths it was asked for."""
    seen: list[str] = []

    class Forward(BaseHTTPRequestHandler):
        def _forward(self) -> None:
            seen.append(self.path)
            if not self.path.startswith(PREFIX + "/"):
                self.send_error(404, "outside the prefix")
                return
            length = int(self.headers.get("Content-Length") or 0)
            r = httpx.request(self.command, stack.url + self.path[len(PREFIX):],
                              content=self.rfile.read(length) if length else None,
                              headers={k: v for k, v in self.headers.items() if k.lower() not in _HOP},
                              follow_redirects=False, timeout=60)
            self.send_response(r.status_code)
            for k, v in r.headers.items():
                if k.lower() not in _HOP:
                    self.send_header(k, v)
            self.send_header("Content-Length", str(len(r.content)))
            self.end_headers()
            self.wfile.write(r.content)

        def do_GET(self) -> None:
            self._forward()

        def do_POST(self) -> None:
            self._forward()

        def log_message(self, *args) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Forward)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}", seen
    server.shutdown()
    server.server_close()


def test_the_page_works_under_a_path_prefix(browser, proxy, tmp_path):
    base, seen = proxy
    context = browser.new_context(viewport=VIEWPORT, base_url=base)
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda exc: problems.append(f"uncaught: {exc}"))
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    try:
        page.goto(PREFIX + "/")
        assert page.url == f"{base}{PREFIX}/app/"
        d = PageDriver(page)
        d.log_in()  # the key is checked with a call to the API, through the prefix
        scene = render_oblique_view(Box(120.0, 80.0, 60.0), seed=2)
        d.add_photos(save_photo(scene, tmp_path / "box.png"))
        expect(page.locator("#next-point")).to_contain_text("Click P1")
    finally:
        context.close()
    assert all(path.startswith(PREFIX + "/") for path in seen), seen
    assert not problems, problems
    assert any(path.startswith(f"{PREFIX}/app/assets/") for path in seen), seen
    assert any(path.startswith(f"{PREFIX}/v1/uploads") for path in seen), seen

"""The rules for https inputs (and webhook targets), against real sockets on 127.0.0.1.

Refusals must happen before any connection: a plain listening socket stands in for an internal
service, and must not have been connected to.
"""

from __future__ import annotations

import io
import socket
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler
from pathlib import Path
from typing import ClassVar

import pytest
from prism_common.references import ReferenceError
from prism_common.settings import Settings

from prism_worker.inputs import FetchError, check_target, fetch_url

from .conftest import API_KEYS, WEBHOOK_SECRET
from .tls import https_server, make_cert

LIMIT = 2000


class _Handler(BaseHTTPRequestHandler):
    hosts: ClassVar[list[str]] = []  # the Host header of every request received

    def do_GET(self) -> None:
        self.hosts.append(self.headers["Host"])
        path, _, query = self.path.partition("?")
        if path == "/ok":
            self._send(200, b"x" * (LIMIT - 1))
        elif path == "/declared-big":
            self._send(200, b"x" * (LIMIT + 1))
        elif path == "/streamed-big":  # no Content-Length: the body ends when the socket does
            self.send_response(200)
            self.end_headers()
            for _ in range(3):
                self.wfile.write(b"y" * 1000)
        elif path == "/pieces":  # a body that arrives in parts, as a large video's would
            self.send_response(200)
            self.end_headers()
            for n in range(3):
                self.wfile.write(bytes([65 + n]) * 500)
                self.wfile.flush()
                time.sleep(0.05)
        elif path == "/redirect":
            self.send_response(302)
            self.send_header("Location", query)
            self.send_header("Content-Length", "0")
            self.end_headers()
        elif path == "/loop":
            self.send_response(301)
            self.send_header("Location", "/loop")
            self.send_header("Content-Length", "0")
            self.end_headers()
        else:
            self._send(404, b"no")

    def _send(self, status: int, body: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args) -> None:
        pass


@pytest.fixture(scope="module")
def cert(tmp_path_factory) -> Path:
    return make_cert(tmp_path_factory.mktemp("tls"))


@pytest.fixture(scope="module")
def https_port(cert) -> Iterator[int]:
    with https_server(cert, _Handler) as port:
        yield port


def _settings(cert: Path | None = None, hosts: tuple[str, ...] = ("localhost",),
              private: bool = True) -> Settings:
    return Settings(api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET, fetch_allowed_hosts=list(hosts),
                    fetch_allow_private=private, fetch_max_bytes=LIMIT,
                    fetch_ca_bundle=str(cert / "cert.pem") if cert else None)


def test_fetches_an_allowed_host_with_its_name_in_host_and_tls(cert, https_port):
    _Handler.hosts.clear()
    assert fetch_url(f"https://localhost:{https_port}/ok", _settings(cert)) == b"x" * (LIMIT - 1)
    # Connected to the checked address, but the server saw the name (Host header; the
    # certificate was verified against it).
    assert _Handler.hosts == [f"localhost:{https_port}"]


def test_a_body_can_be_streamed_into_a_file_as_it_arrives(cert, https_port):
    writes: list[int] = []

    class Recorder(io.BytesIO):
        def write(self, data) -> int:
            writes.append(len(data))
            return super().write(data)

    dest = Recorder()
    assert fetch_url(f"https://localhost:{https_port}/redirect?/pieces", _settings(cert), dest) == b""
    assert dest.getvalue() == b"A" * 500 + b"B" * 500 + b"C" * 500
    assert len(writes) > 1 and max(writes) < 1500  # written part by part, never held whole


def test_certificates_are_verified(https_port):
    with pytest.raises(FetchError, match=r"CERTIFICATE_VERIFY_FAILED|certificate verify failed"):
        fetch_url(f"https://localhost:{https_port}/ok", _settings(None))


@pytest.mark.parametrize("url", [
    "https://127.0.0.1:{port}/x",  # a host that is not on the list, although it resolves
    "https://LOCALHOST.:{port}/x",  # no trailing-dot or case games: not the listed name
    "http://localhost:{port}/x",  # plain http
    "ftp://localhost:{port}/x",
    "file:///etc/passwd",
    "gopher://localhost:{port}/x",
    "https://user:secret@localhost:{port}/x",  # credentials
])
def test_refused_before_connecting(listener, url):
    port = listener.getsockname()[1]
    with pytest.raises(ReferenceError):
        fetch_url(url.format(port=port), _settings())


@pytest.mark.parametrize("host", ["localhost", "127.0.0.1", "169.254.169.254", "10.0.0.7",
                                  "192.168.1.1", "0.0.0.0", "::1", "fd00::1"])
def test_private_and_link_local_addresses_are_refused(listener, host):
    port = listener.getsockname()[1]
    netloc = f"[{host}]" if ":" in host else host
    with pytest.raises(ReferenceError, match="private or local"):
        fetch_url(f"https://{netloc}:{port}/latest/meta-data", _settings(hosts=(host,), private=False))


def test_redirect_is_followed_to_an_allowed_host(cert, https_port):
    url = f"https://localhost:{https_port}/redirect?/ok"
    assert len(fetch_url(url, _settings(cert))) == LIMIT - 1


@pytest.mark.parametrize("target", ["https://127.0.0.1:{port}/", "http://localhost:{port}/",
                                    "https://169.254.169.254:{port}/"])
def test_redirect_to_a_refused_target_is_not_followed(cert, https_port, listener, target):
    target = target.format(port=listener.getsockname()[1])
    with pytest.raises(ReferenceError):
        fetch_url(f"https://localhost:{https_port}/redirect?{target}", _settings(cert))


def test_redirects_are_limited(cert, https_port):
    with pytest.raises(FetchError, match="more than 3 redirects"):
        fetch_url(f"https://localhost:{https_port}/loop", _settings(cert))


@pytest.mark.parametrize("path", ["/declared-big", "/streamed-big"])
def test_size_limit(cert, https_port, path):
    with pytest.raises(FetchError, match=f"limit of {LIMIT} bytes"):
        fetch_url(f"https://localhost:{https_port}{path}", _settings(cert))


def test_http_errors_fail_with_the_status(cert, https_port):
    with pytest.raises(FetchError, match="HTTP 404"):
        fetch_url(f"https://localhost:{https_port}/missing", _settings(cert))


def test_nothing_listening_is_a_fetch_error(cert):
    with socket.socket() as sock:  # a port that was free a moment ago
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    with pytest.raises(FetchError, match="cannot fetch"):
        fetch_url(f"https://localhost:{port}/ok", _settings(cert))


def test_webhook_targets_have_their_own_rules():
    target = check_target("http://127.0.0.1:9/hook", schemes={"http", "https"},
                          allowed_hosts=["127.0.0.1"], allow_private=True)
    assert target.addresses == ["127.0.0.1"] and target.netloc == "127.0.0.1:9"
    with pytest.raises(ReferenceError, match="private or local"):
        check_target("http://127.0.0.1:9/hook", schemes={"http", "https"},
                     allowed_hosts=["127.0.0.1"], allow_private=False)
    with pytest.raises(ReferenceError, match="allow-list"):
        check_target("https://example.com/hook", schemes={"http", "https"},
                     allowed_hosts=["127.0.0.1"], allow_private=True)


@pytest.mark.parametrize("entry", ["LocalHost", "localhost.", " localhost "])
def test_allow_list_entries_are_matched_as_host_names(entry):
    # The API checks a webhook URL at submit, the worker again at delivery: both must read the
    # operator's list the same way, whatever its case.
    settings = Settings(api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET,
                        webhook_allowed_hosts=[entry], fetch_allowed_hosts=[entry])
    assert settings.webhook_allowed_hosts == settings.fetch_allowed_hosts == ["localhost"]
    target = check_target("http://LOCALHOST:8080/hook", schemes={"http"},
                          allowed_hosts=settings.webhook_allowed_hosts, allow_private=True)
    assert target.host == "localhost"

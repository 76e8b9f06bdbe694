"""A TLS certificate for localhost and HTTPS servers on 127.0.0.1 that use it: the far side of
https inputs (the service is pointed at the certificate with PRISM_FETCH_CA_BUNDLE)."""

from __future__ import annotations

import shutil
import ssl
import subprocess
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

__all__ = ["https_server", "make_cert"]


def make_cert(folder: Path) -> Path:
    """Write a self-signed cert.pem and key.pem for localhost into `folder`; returns it."""
    # openssl is on every machine this project runs on; missing, the test must fail, not pass.
    assert shutil.which("openssl"), "the openssl command is needed to make a test certificate"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2",
                    "-keyout", str(folder / "key.pem"), "-out", str(folder / "cert.pem"),
                    "-subj", "/CN=localhost", "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"],
                   check=True, capture_output=True)
    return folder


@contextmanager
def https_server(cert: Path, handler: type[BaseHTTPRequestHandler]) -> Iterator[int]:
    """Serve `handler` over TLS on 127.0.0.1 (threaded); yields the port."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(cert / "cert.pem", cert / "key.pem")
    server.socket = context.wrap_socket(server.socket, server_side=True)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()

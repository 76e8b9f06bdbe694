"""Outgoing HTTP to hosts that users name (input URLs, webhook URLs).

The rules are checked before any connection is made: the scheme, the host's place on an
allow-list, and every address the host resolves to (public only, unless a test allows
loopback). The request then goes to the address that was checked, with the name in the Host
header and in TLS SNI (certificates are still verified against the name), so a DNS answer
that changes between the check and the connection cannot redirect us to an internal address.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from urllib.parse import urlsplit

import httpx
from prism_common.references import ReferenceError, resolve_public

__all__ = ["Target", "check_target", "send_pinned"]

_DEFAULT_PORTS = {"http": 80, "https": 443}


@dataclass(frozen=True)
class Target:
    url: httpx.URL
    host: str
    netloc: str  # host[:port] as the Host header carries it
    addresses: list[str]


def check_target(url: str, *, schemes: Collection[str],
                 allowed_hosts: Collection[str], allow_private: bool) -> Target:
    """Parse `url` and apply the rules; ReferenceError (saying which) if it may not be called."""
    try:
        parts = urlsplit(url)
        port = parts.port or _DEFAULT_PORTS.get(parts.scheme, 0)
    except ValueError:
        raise ReferenceError(f"{url[:200]!r} is not a valid URL") from None
    if parts.scheme not in schemes:
        raise ReferenceError(f"{url[:200]!r}: only {' or '.join(sorted(schemes))} URLs are allowed")
    host = (parts.hostname or "").lower()
    if not host:
        raise ReferenceError(f"{url[:200]!r} names no host")
    if parts.username or parts.password:
        raise ReferenceError(f"credentials in URLs are not accepted: {host!r}")
    if host not in allowed_hosts:
        raise ReferenceError(f"host {host!r} is not on the allow-list")
    addresses = resolve_public(host, port, allow_private=allow_private)
    netloc = host if port == _DEFAULT_PORTS[parts.scheme] else f"{host}:{port}"
    return Target(httpx.URL(url), host, netloc, addresses)


@contextmanager
def send_pinned(client: httpx.Client, method: str, target: Target, *, content: bytes | None = None,
                headers: dict[str, str] | None = None) -> Iterator[httpx.Response]:
    """Send to the checked addresses in turn (the first that accepts), streaming the answer.

    Redirects are never followed here: the caller checks where they point first.
    """
    error: httpx.ConnectError | None = None
    for address in target.addresses:
        request = client.build_request(
            method, target.url.copy_with(host=address), content=content,
            headers={**(headers or {}), "Host": target.netloc},
            extensions={"sni_hostname": target.host})
        try:
            response = client.send(request, stream=True, follow_redirects=False)
        except httpx.ConnectError as exc:
            error = exc
            continue
        try:
            yield response
        finally:
            response.close()
        return
    assert error is not None  # resolve_public never returns an empty list
    raise error

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

import httpx
from prism_common.outbound import CheckedURL, check_url

__all__ = ["Target", "check_target", "pinned", "send_pinned"]


@dataclass(frozen=True)
class Target:
    url: httpx.URL
    host: str
    netloc: str  # host[:port] as the Host header carries it
    addresses: list[str]


def check_target(url: str, *, schemes: Collection[str],
                 allowed_hosts: Collection[str], allow_private: bool) -> Target:
    """Parse `url` and apply the rules (`prism_common.outbound.check_url`); ReferenceError
    (saying which) if it may not be called."""
    return pinned(check_url(url, schemes=schemes, allowed_hosts=allowed_hosts, allow_private=allow_private))


def pinned(checked: CheckedURL) -> Target:
    """The target of a URL checked with its addresses resolved."""
    assert checked.addresses, "check the URL with resolve=True"
    return Target(httpx.URL(checked.url), checked.host, checked.netloc, list(checked.addresses))


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

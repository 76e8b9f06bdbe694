"""The rules for URLs the service itself calls: ``https`` inputs and webhook targets.

Everything is checked before a connection is made: the scheme, no credentials in the URL, the
host on an allow-list, and every address the host resolves to public (loopback and private
ones only where a setting allows them). The worker then connects to the very addresses checked
(`prism_worker.inputs`), so a DNS answer that changes in between cannot point it inside.

Webhooks have one policy, `check_webhook_url`, applied by the API when a job is submitted (422)
and by the worker before each delivery:

* ``https`` always; ``http`` only with ``PRISM_WEBHOOK_ALLOW_HTTP=true`` (a receiver on a
  trusted network, e.g. one on the same machine as ``prism serve``);
* the host on ``PRISM_WEBHOOK_ALLOWED_HOSTS``; no user or password in the URL;
* every address of the host public, unless ``PRISM_WEBHOOK_ALLOW_PRIVATE=true``. The API does
  not resolve the name (a DNS lookup would hold the request, and the answer that matters is the
  one at delivery time); the worker does, at each delivery.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

from .references import ReferenceError, resolve_public

if TYPE_CHECKING:
    from .settings import Settings

__all__ = ["CheckedURL", "check_url", "check_webhook_url", "webhook_schemes"]

_DEFAULT_PORTS = {"http": 80, "https": 443}


@dataclass(frozen=True)
class CheckedURL:
    """A URL that passed the rules, with what a pinned connection to it needs."""

    url: str
    scheme: str
    host: str  # lowercased
    port: int
    netloc: str  # host[:port] as the Host header carries it
    addresses: tuple[str, ...]  # what the host resolved to; () when not resolved


def check_url(url: str, *, schemes: Collection[str], allowed_hosts: Collection[str],
              allow_private: bool, resolve: bool = True) -> CheckedURL:
    """Parse `url` and apply the rules; ReferenceError (saying which, quoting the URL or host)
    if the service may not call it. `resolve=False` skips the address rule (and DNS)."""
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
    addresses = tuple(resolve_public(host, port, allow_private=allow_private)) if resolve else ()
    netloc = host if port == _DEFAULT_PORTS[parts.scheme] else f"{host}:{port}"
    return CheckedURL(url, parts.scheme, host, port, netloc, addresses)


def webhook_schemes(settings: Settings) -> frozenset[str]:
    return frozenset({"https", "http"} if settings.webhook_allow_http else {"https"})


def check_webhook_url(url: str, settings: Settings, *, resolve: bool = True) -> CheckedURL:
    """The webhook policy (module docstring): the checked URL, or ReferenceError saying why not.

    The API calls it with ``resolve=False`` at submit, the worker with ``resolve=True`` before
    each delivery, so both refuse by the same rule.
    """
    try:
        scheme = urlsplit(url).scheme
    except ValueError:
        scheme = ""  # check_url says what is wrong with it
    if scheme == "http" and not settings.webhook_allow_http:
        raise ReferenceError(f"{url[:200]!r}: webhooks are sent to https URLs only (http needs "
                             "PRISM_WEBHOOK_ALLOW_HTTP=true on the service)")
    return check_url(url, schemes=webhook_schemes(settings), allowed_hosts=settings.webhook_allowed_hosts,
                     allow_private=settings.webhook_allow_private, resolve=resolve)

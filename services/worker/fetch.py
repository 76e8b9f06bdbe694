"""Fetch an ``https`` input: allow-listed hosts on public addresses, redirects checked hop by hop.

Nothing is followed automatically: each redirect's target goes through the same checks before
it is connected to, at most MAX_REDIRECTS times. The body is streamed and refused as soon as it
passes the size limit, and the whole fetch has a deadline, so a slow or endless answer cannot
hold a scan worker.
"""

from __future__ import annotations

import ssl
import time
from typing import BinaryIO

import httpx
from prism_common.settings import Settings

from .egress import check_target, send_pinned

__all__ = ["MAX_REDIRECTS", "FetchError", "fetch_url"]

MAX_REDIRECTS = 3
TIMEOUT = httpx.Timeout(30.0, connect=5.0)
DEADLINE_S = 120.0


class FetchError(Exception):
    """The input could not be fetched (HTTP error, too large, too slow); the message says why."""


def _client(settings: Settings) -> httpx.Client:
    # trust_env=False: a proxy from the environment would connect on our behalf, unchecked.
    context = ssl.create_default_context(cafile=settings.fetch_ca_bundle)
    return httpx.Client(verify=context, timeout=TIMEOUT, trust_env=False, follow_redirects=False)


def _read(response: httpx.Response, url: str, limit: int, deadline: float,
          dest: BinaryIO | None) -> bytes:
    """The body (or, given `dest`, b"" and the body written into it as it comes)."""
    declared = response.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise FetchError(f"{url} is {int(declared)} bytes, over the limit of {limit} bytes")
    chunks, size = [], 0
    for chunk in response.iter_bytes():
        size += len(chunk)
        if size > limit:
            raise FetchError(f"{url} is larger than the limit of {limit} bytes")
        if time.monotonic() > deadline:
            raise FetchError(f"{url} took longer than {DEADLINE_S:g} s to download")
        if dest is None:
            chunks.append(chunk)
        else:
            dest.write(chunk)
    return b"".join(chunks)


def fetch_url(url: str, settings: Settings, dest: BinaryIO | None = None) -> bytes:
    """The body of `url`; or, given `dest`, b"" and the body streamed into it (a video is never
    held whole; on an error `dest` may hold part of it).

    Raises
    ------
    ReferenceError
        A URL (the given one or a redirect's) the rules refuse; nothing was sent to it.
    FetchError
        The server's answer: an HTTP error, too many redirects, too large, too slow, no answer.
    """
    deadline = time.monotonic() + DEADLINE_S
    with _client(settings) as client:
        for _ in range(MAX_REDIRECTS + 1):
            target = check_target(url, schemes={"https"},
                                  allowed_hosts=settings.fetch_allowed_hosts,
                                  allow_private=settings.fetch_allow_private)
            try:
                with send_pinned(client, "GET", target) as response:
                    if response.is_redirect:
                        location = response.headers.get("location", "")
                        if not location:
                            raise FetchError(f"{url} answered {response.status_code} without a Location")
                        url = str(target.url.join(location))
                        continue
                    if response.status_code != 200:
                        raise FetchError(f"{url} answered HTTP {response.status_code}")
                    return _read(response, url, settings.fetch_max_bytes, deadline, dest)
            except httpx.HTTPError as exc:
                raise FetchError(f"cannot fetch {url}: {exc or type(exc).__name__}") from None
        raise FetchError(f"{url}: more than {MAX_REDIRECTS} redirects")

"""An item's inputs: read where their references point, with the rules checked again here.

References (`prism_common.references`): ``upload:{id}`` (the service's bucket), ``s3://bucket/key``
(a bucket the operator lets it read), ``https://...`` (an allow-listed host). A tiled item's
photos are copied into the job's prefix (`copy_input`), so its later tasks (tiles, finish, a
re-run of the plan) read the service's own bucket only. A batch item reads its photo directly
(`read_input`); a video is streamed to a local file (`save_input`) and split from there.

Outgoing HTTP to hosts that users name (input URLs here, webhook URLs in webhooks.py): the rules
are checked before any connection is made: the scheme, the host's place on an allow-list, and
every address the host resolves to (public only, unless a test allows loopback). The request
then goes to the address that was checked, with the name in the Host header and in TLS SNI
(certificates are still verified against the name), so a DNS answer that changes between the
check and the connection cannot redirect us to an internal address.

Fetching an ``https`` input follows no redirect automatically: each redirect's target goes
through the same checks before it is connected to, at most MAX_REDIRECTS times. The body is
streamed and refused as soon as it passes the size limit, and the whole fetch has a deadline,
so a slow or endless answer cannot hold a scan worker.
"""

from __future__ import annotations

import shutil
import ssl
import time
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import BinaryIO

import httpx
from botocore.exceptions import ClientError
from prism_common.outbound import CheckedURL, check_url
from prism_common.records import ItemView
from prism_common.references import ReferenceError, check_reference, parse_reference
from prism_common.settings import Settings
from prism_common.storage import is_missing

from .artifacts import item_key
from .context import WorkerContext

__all__ = ["MAX_REDIRECTS", "FetchError", "Target", "check_target", "copy_input", "fetch_url", "pinned",
           "read_input", "read_reference", "save_input", "send_pinned"]


# -- egress: calling a host a user named ---------------------------------------------------------
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


# -- fetch: an https input ---------------------------------------------------------------------
MAX_REDIRECTS = 3
TIMEOUT = httpx.Timeout(30.0, connect=5.0)
DEADLINE_S = 120.0


class FetchError(Exception):
    """The input could not be fetched (HTTP error, too large, too slow); the message says why."""


def _client(settings: Settings) -> httpx.Client:
    # trust_env=False: a proxy from the environment would connect on our behalf, unchecked.
    tls = ssl.create_default_context(cafile=settings.fetch_ca_bundle)
    return httpx.Client(verify=tls, timeout=TIMEOUT, trust_env=False, follow_redirects=False)


def _read_body(response: httpx.Response, url: str, limit: int, deadline: float,
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
                    return _read_body(response, url, settings.fetch_max_bytes, deadline, dest)
            except httpx.HTTPError as exc:
                raise FetchError(f"cannot fetch {url}: {exc or type(exc).__name__}") from None
        raise FetchError(f"{url}: more than {MAX_REDIRECTS} redirects")


# -- references: the item's inputs -------------------------------------------------------------
# Besides a missing object: a bucket that is not there or not ours to read is "no object" too.
_UNREADABLE = {"403", "AccessDenied", "NoSuchBucket"}
_CHUNK = 1 << 20


def _read_s3(ctx: WorkerContext, bucket: str, key: str, text: str, limit: int,
             dest: BinaryIO | None = None) -> bytes:
    """The object's bytes; or, given `dest`, the object streamed into it (and b"")."""
    try:
        obj = ctx.objects.client.get_object(Bucket=bucket, Key=key)
    except ClientError as exc:
        if is_missing(exc) or exc.response.get("Error", {}).get("Code") in _UNREADABLE:
            raise ReferenceError(f"no object {text!r}") from None
        raise  # anything else is the store's trouble, retried by the task
    with obj["Body"] as body:
        if obj.get("ContentLength", 0) > limit:
            raise ReferenceError(f"{text!r} is {obj['ContentLength']} bytes, over the limit of {limit}")
        if dest is None:
            data: bytes = body.read()
            return data
        shutil.copyfileobj(body, dest, _CHUNK)
        return b""


def _read_reference(ctx: WorkerContext, text: str, tenant: str,
                    dest: BinaryIO | None = None) -> tuple[bytes, str]:
    """The bytes a reference names (or, given `dest`, b"" and the bytes written into it), and the
    name to quote in error messages."""
    ref = parse_reference(text)
    settings = ctx.settings
    upload = ctx.store.get_upload(ref.upload_id) if ref.kind == "upload" else None
    # The API checked the reference when the job came in; the rules (or the upload) may have
    # changed since, so they are checked again where the bytes are read.
    check_reference(ref, settings, tenant=tenant, upload_owner=upload["tenant"] if upload else None)
    if ref.kind == "upload":
        assert upload is not None
        data = _read_s3(ctx, ctx.objects.bucket, upload["key"], text, settings.upload_max_bytes, dest)
        return data, upload.get("name") or text
    if ref.kind == "s3":
        return _read_s3(ctx, ref.bucket, ref.key, text, settings.fetch_max_bytes, dest), text
    return fetch_url(ref.url, settings, dest), ref.url


def read_input(ctx: WorkerContext, view: ItemView, which: str) -> tuple[bytes, str]:
    """The bytes of the item's `which` ("front" or "side") photo, read where its reference
    points (not copied), and the name to quote in error messages.

    Raises ReferenceError or FetchError, as `copy_input` does.
    """
    spec = view.item.spec
    text = spec.image if which == "front" else spec.side_image
    assert text is not None
    return _read_reference(ctx, text, view.tenant)


def read_reference(ctx: WorkerContext, text: str, tenant: str) -> tuple[bytes, str]:
    """The bytes of one of the item's inputs named by its reference `text` (a view of a joint
    item), read where it points, and the name to quote. Raises as `read_input` does."""
    return _read_reference(ctx, text, tenant)


def save_input(ctx: WorkerContext, view: ItemView, which: str, dest: BinaryIO) -> str:
    """Stream the item's `which` input into `dest` (a video: never whole in memory); the name
    to quote in error messages. Raises ReferenceError or FetchError, as `copy_input` does."""
    text = view.item.spec.image if which == "front" else view.item.spec.side_image
    assert text is not None
    return _read_reference(ctx, text, view.tenant, dest)[1]


def copy_input(ctx: WorkerContext, view: ItemView, which: str) -> tuple[str, str]:
    """Copy the item's `which` ("front" or "side") photo into the job's prefix, unless done.

    Returns the object key and the name to quote in error messages (the uploaded file's name,
    or the reference).

    Raises
    ------
    ReferenceError
        A reference the service will not read, or one that names nothing.
    FetchError
        An https input that could not be fetched.
    """
    spec = view.item.spec
    text = spec.image if which == "front" else spec.side_image
    assert text is not None
    key = item_key(view.job_id, view.item.index, which)
    objects = ctx.objects
    if objects.exists(key):
        return key, _label(ctx, text)
    data, label = _read_reference(ctx, text, view.tenant)
    objects.put_bytes(key, data)
    return key, label


def _label(ctx: WorkerContext, text: str) -> str:
    ref = parse_reference(text)
    if ref.kind == "upload":
        upload = ctx.store.get_upload(ref.upload_id)
        return (upload or {}).get("name") or text
    return text

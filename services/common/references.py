"""Input references an item may carry, and the rules for what the service will read.

* ``s3://bucket/key``: an object in a bucket the service is configured to read;
* ``upload:{id}``: a file uploaded through ``POST /v1/uploads`` by the same tenant;
* ``https://host/path``: a URL on an allow-listed host that resolves to a public address.
"""

from __future__ import annotations

import ipaddress
import re
import socket
from dataclasses import dataclass
from urllib.parse import urlsplit

from .settings import Settings

__all__ = ["Reference", "ReferenceError", "check_reference", "is_public_ip", "parse_reference",
           "resolve_public"]

_UPLOAD = re.compile(r"^upload:([0-9a-f]{32})$")
_S3 = re.compile(r"^s3://([a-z0-9][a-z0-9.-]{1,61}[a-z0-9])/(.+)$")


class ReferenceError(ValueError):
    """A reference the service will not read; the message says why."""


@dataclass(frozen=True)
class Reference:
    kind: str  # "s3", "upload" or "https"
    bucket: str = ""
    key: str = ""
    upload_id: str = ""
    url: str = ""
    host: str = ""


def parse_reference(text: str) -> Reference:
    """Parse a reference string; ReferenceError quoting it if it is none of the three kinds."""
    if m := _UPLOAD.match(text):
        return Reference("upload", upload_id=m[1])
    if m := _S3.match(text):
        key = m[2]
        if key.startswith("/") or any(p in ("", ".", "..") for p in key.split("/")):
            raise ReferenceError(f"unsafe object key in {text!r}")
        return Reference("s3", bucket=m[1], key=key)
    parts = urlsplit(text)
    if parts.scheme == "https" and parts.hostname:
        if parts.username or parts.password:
            raise ReferenceError(f"credentials in URLs are not accepted: {parts.hostname!r}")
        return Reference("https", url=text, host=parts.hostname.lower())
    if text.startswith("upload:"):  # the form named, its id not: say what an id is
        raise ReferenceError(
            f"{text[:200]!r} is not an upload id: an upload's id is the 32 lowercase hex digits "
            "POST /v1/uploads answered (its reference, upload:ID)")
    raise ReferenceError(
        f"{text[:200]!r} is not a reference: use upload:ID, s3://bucket/key or an https URL")


# IPv6 ranges that carry an IPv4 address a gateway may deliver to: NAT64's well-known prefix
# (RFC 6052) and the deprecated IPv4-compatible form; 6to4 and mapped ones have ipaddress helpers.
_NAT64 = ipaddress.ip_network("64:ff9b::/96")
_COMPATIBLE = ipaddress.ip_network("::/96")
_LOCAL_NAT64 = ipaddress.ip_network("64:ff9b:1::/48")  # RFC 8215: local use, yet "global" to ipaddress


def _embedded_ipv4(ip: ipaddress.IPv6Address) -> ipaddress.IPv4Address | None:
    if ip.ipv4_mapped or ip.sixtofour:
        return ip.ipv4_mapped or ip.sixtofour
    if ip in _NAT64 or (ip in _COMPATIBLE and int(ip) > 1):
        return ipaddress.IPv4Address(int(ip) & 0xFFFFFFFF)
    return None


def is_public_ip(address: str) -> bool:
    """False for loopback, private, link-local (169.254.x.x), multicast, reserved addresses, and
    for IPv6 addresses that embed one of those (mapped, 6to4, NAT64, IPv4-compatible)."""
    ip = ipaddress.ip_address(address)
    if isinstance(ip, ipaddress.IPv6Address):
        if ip in _LOCAL_NAT64:
            return False
        ip = _embedded_ipv4(ip) or ip
    return ip.is_global and not ip.is_multicast


def resolve_public(host: str, port: int, *, allow_private: bool) -> list[str]:
    """The addresses `host` resolves to, all of which must be public (unless `allow_private`,
    a switch for tests).

    Raises ReferenceError before any connection is made.
    """
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ReferenceError(f"cannot resolve {host!r}: {exc.strerror}") from None
    addresses = sorted({str(info[4][0]) for info in infos})  # str for IPv4 and IPv6 (typeshed: str | int)
    if not allow_private and not all(is_public_ip(a) for a in addresses):
        raise ReferenceError(f"{host!r} resolves to a private or local address; not fetched")
    return addresses


def check_reference(ref: Reference, settings: Settings, *, tenant: str,
                    upload_owner: str | None) -> None:
    """Refuse what the service must not read (ReferenceError with the reason).

    `upload_owner` is the tenant an ``upload:`` reference's file belongs to (None if unknown).
    """
    if ref.kind == "s3" and ref.bucket not in settings.readable_buckets:
        raise ReferenceError(f"bucket {ref.bucket!r} is not one the service may read")
    if ref.kind == "upload" and upload_owner != tenant:
        raise ReferenceError(f"no upload {ref.upload_id!r}")  # another tenant's is "no upload"
    if ref.kind == "https" and ref.host not in settings.fetch_allowed_hosts:
        raise ReferenceError(f"host {ref.host!r} is not on the fetch allow-list")

"""Dependencies of the routes, and their `Annotated` aliases.

Everything comes from `get_settings`, so a test overrides that one dependency and the store,
object storage and Celery app follow. Clients are built once per configuration and shared by
requests (connection pools), not once per request.
"""

from __future__ import annotations

import hmac
import ipaddress
import threading
from collections.abc import Callable
from typing import Annotated, TypeVar

import redis
from celery import Celery
from fastapi import Depends, HTTPException, Request, Security, status
from fastapi.security import APIKeyHeader
from prism_common.queue import make_celery
from prism_common.redis_client import redis_client
from prism_common.settings import Settings, get_settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

from .presign import Presigner
from .ratelimit import RateLimiter

__all__ = ["CeleryDep", "ObjectsDep", "PresignerDep", "RedisDep", "SettingsDep", "StoreDep",
           "TenantDep", "get_celery", "get_objects", "get_presigner", "get_rate_limited_tenant",
           "get_redis", "get_store", "get_tenant"]

T = TypeVar("T")
_lock = threading.Lock()
_built: dict[tuple, object] = {}


def _once(key: tuple, build: Callable[[], T]) -> T:
    # Settings objects are not hashable, so each client is keyed by the settings it is built from.
    with _lock:
        if key not in _built:
            _built[key] = build()
        return _built[key]  # type: ignore[return-value]


SettingsDep = Annotated[Settings, Depends(get_settings)]


def get_redis(settings: SettingsDep) -> redis.Redis:
    # Timeouts: a stuck Redis fails the request (503) instead of holding it forever.
    return _once(("redis", settings.redis_url, *settings.redis_sentinels), lambda: redis_client(
        settings, socket_connect_timeout=5, socket_timeout=15, health_check_interval=30))


RedisDep = Annotated[redis.Redis, Depends(get_redis)]


def get_store(settings: SettingsDep, client: RedisDep) -> JobStore:
    return _once(("store", settings.redis_url), lambda: JobStore(client))


def _s3(settings: Settings, *, for_links: bool = False) -> tuple:
    """What an S3 client is built from, as a key for _once."""
    key_id, secret = settings.s3_access_key_id, settings.s3_secret_access_key
    endpoint = (for_links and settings.s3_public_endpoint_url) or settings.s3_endpoint_url
    return (endpoint, settings.s3_region, settings.s3_bucket,
            key_id.get_secret_value() if key_id else None,
            secret.get_secret_value() if secret else None)


def get_objects(settings: SettingsDep) -> ObjectStore:
    return _once(("s3", *_s3(settings)), lambda: ObjectStore.from_settings(settings))


def get_presigner(settings: SettingsDep) -> Presigner:
    # Its own client: links are signed for the host clients reach (s3_public_endpoint_url).
    return _once(("presign", *_s3(settings, for_links=True), settings.presign_ttl_s),
                 lambda: Presigner(ObjectStore.from_settings(settings, for_links=True),
                                   settings.presign_ttl_s))


def get_celery(settings: SettingsDep) -> Celery:
    # make_celery reads the broker URL and the visibility timeout, nothing else.
    return _once(("celery", settings.redis_url, settings.visibility_timeout_s),
                 lambda: make_celery(settings))


_api_key = APIKeyHeader(name="X-API-Key", auto_error=False,
                        description="The key of your tenant; every /v1 call needs it.")


def get_rate_limiter(settings: SettingsDep, client: RedisDep) -> RateLimiter:
    return _once(("rate", settings.redis_url, settings.rate_limit_per_minute),
                 lambda: RateLimiter(client, settings.rate_limit_per_minute))


def get_auth_failure_limiter(settings: SettingsDep, client: RedisDep) -> RateLimiter:
    return _once(("authfail", settings.redis_url, settings.auth_failures_per_minute),
                 lambda: RateLimiter(client, settings.auth_failures_per_minute, scope="authfail"))


def _too_many(message: str, limiter: RateLimiter, wait: float, request: Request) -> HTTPException:
    return HTTPException(status.HTTP_429_TOO_MANY_REQUESTS, f"{message}; retry in {wait:.1f} s",
                         headers={"Retry-After": limiter.retry_after(wait), **_closing(request)})


def _closing(request: Request) -> dict[str, str]:
    """`Connection: close` for a refusal of a request whose body may not have been read.

    The key is checked from the headers, before a route that streams its body (an upload, a
    station's photos) reads a byte of it; answered on a kept-alive connection, the server would
    then read the rest of the body, however large, to find the next request (3 GB taken in at
    ~1 GB/s for a 401, issue 37). Closed instead: uvicorn stops reading once the answer is sent.
    """
    headers = request.headers
    pending = headers.get("content-length", "0") not in ("", "0") or "transfer-encoding" in headers
    return {"Connection": "close"} if pending else {}


def client_address(request: Request) -> str:
    """Who is calling, for the refused-key budget: the client's IPv4 address, or its IPv6 /64
    (one host can hold a whole /64, so a budget per address would be no budget)."""
    host = request.client.host if request.client else "unknown"
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host
    if isinstance(address, ipaddress.IPv6Address):
        if address.ipv4_mapped is not None:
            return str(address.ipv4_mapped)
        return str(ipaddress.ip_network(f"{address}/64", strict=False))
    return str(address)


def get_tenant(settings: SettingsDep, request: Request,
               api_key: Annotated[str | None, Security(_api_key)],
               failures: Annotated[RateLimiter, Depends(get_auth_failure_limiter)]) -> str:
    """The tenant whose key came in the X-API-Key header; 401 otherwise.

    A refused key takes a token from its address's refused-key budget; with the budget spent,
    the address's refused keys get 429 instead of 401. A right key never touches the budget and
    is never locked out by it (issue 37: one bad client behind a NAT or proxy locked out everyone
    behind it): it answers to the per-key rate limit alone. A call with no key at all cannot be
    a guess and costs nothing. The budget bounds what refused keys cost the service; it cannot
    stop a guesser telling a right key (200) from the refused ones (429) without locking valid
    keys out again, so keys must be long random tokens (`prism serve` makes 192-bit ones).
    """
    given = (api_key or "").encode()
    if not given:
        raise _unauthorized(request)
    tenant = None
    # Every key is compared, in constant time, whichever matches: the time taken says nothing
    # about which key (or how much of one) was right.
    for name, key in settings.api_keys.items():
        if hmac.compare_digest(given, key.get_secret_value().encode()):
            tenant = name
    if tenant is not None:
        return tenant
    # One atomic step: a refused key is counted only if the budget has room for it, so guesses
    # sent at once cannot overdraw it.
    wait = failures.wait_s(client_address(request))
    if wait > 0:
        raise _too_many(f"too many refused API keys from this address (limit "
                        f"{failures.per_minute} a minute)", failures, wait, request)
    raise _unauthorized(request)


def _unauthorized(request: Request) -> HTTPException:
    return HTTPException(status.HTTP_401_UNAUTHORIZED, "missing or invalid X-API-Key header",
                         headers={"WWW-Authenticate": "ApiKey", **_closing(request)})


def get_rate_limited_tenant(tenant: Annotated[str, Depends(get_tenant)], request: Request,
                            limiter: Annotated[RateLimiter, Depends(get_rate_limiter)]) -> str:
    """The caller's tenant, once its call fits the per-key rate limit; 429 + Retry-After if not."""
    wait = limiter.wait_s(tenant)
    if wait > 0:
        raise _too_many(f"rate limit of {limiter.per_minute} calls a minute exceeded for this key",
                        limiter, wait, request)
    return tenant


StoreDep = Annotated[JobStore, Depends(get_store)]
ObjectsDep = Annotated[ObjectStore, Depends(get_objects)]
PresignerDep = Annotated[Presigner, Depends(get_presigner)]
CeleryDep = Annotated[Celery, Depends(get_celery)]
TenantDep = Annotated[str, Depends(get_rate_limited_tenant)]

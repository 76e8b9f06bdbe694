"""How every process reaches Redis: one server at ``redis_url``, or the primary that Sentinel
names (``redis_sentinels`` + ``redis_sentinel_master``).

Behind Sentinel, a client asks the sentinels where the primary is when it connects and again
after a connection error, so after a failover its next retried command lands on the promoted
replica. The Celery broker and result backend get the same addresses as ``sentinel://`` URLs
with the primary's name in their transport options (`celery_url`, `celery_transport_options`).
"""

from __future__ import annotations

from typing import Any
from urllib.parse import quote

import redis
import redis.asyncio as aioredis
from redis.asyncio.sentinel import Sentinel as AsyncSentinel
from redis.connection import parse_url
from redis.sentinel import Sentinel

from .settings import Settings

__all__ = ["async_redis_client", "celery_transport_options", "celery_url", "redis_client",
           "sentinel_addresses"]

# Sentinels answer from memory: a short timeout moves on to the next one quickly.
_SENTINEL_TIMEOUT_S = 2.0


def sentinel_addresses(settings: Settings) -> list[tuple[str, int]]:
    """The sentinels as (host, port); empty when Redis is a single server."""
    out = []
    for address in settings.redis_sentinels:
        host, _, port = address.rpartition(":")
        out.append((host.strip("[]"), int(port)))
    return out


def _primary_params(settings: Settings) -> dict[str, Any]:
    # redis_url's password, user name and database apply to the primary Sentinel names.
    params = parse_url(settings.redis_url)
    return {k: params[k] for k in ("db", "username", "password") if params.get(k) is not None}


def _sentinel_kwargs(settings: Settings) -> dict[str, Any]:
    kwargs: dict[str, Any] = {"socket_timeout": _SENTINEL_TIMEOUT_S,
                              "socket_connect_timeout": _SENTINEL_TIMEOUT_S}
    if settings.redis_sentinel_password is not None:
        kwargs["password"] = settings.redis_sentinel_password.get_secret_value()
    return kwargs


def redis_client(settings: Settings, *, decode_responses: bool = True, **options: Any) -> redis.Redis:
    """A client for the settings' Redis (the primary, behind Sentinel); `options` are redis-py's
    connection options (timeouts, health_check_interval)."""
    if not settings.redis_sentinels:
        return redis.Redis.from_url(settings.redis_url, decode_responses=decode_responses, **options)
    sentinel = Sentinel(sentinel_addresses(settings), sentinel_kwargs=_sentinel_kwargs(settings))
    client: redis.Redis = sentinel.master_for(settings.redis_sentinel_master, redis_class=redis.Redis,
                                              decode_responses=decode_responses,
                                              **_primary_params(settings), **options)
    return client


def async_redis_client(settings: Settings, **options: Any) -> aioredis.Redis:
    """`redis_client`'s asyncio counterpart (bytes replies)."""
    if not settings.redis_sentinels:
        return aioredis.Redis.from_url(settings.redis_url, **options)
    sentinel = AsyncSentinel(sentinel_addresses(settings), sentinel_kwargs=_sentinel_kwargs(settings))
    client: aioredis.Redis = sentinel.master_for(settings.redis_sentinel_master, redis_class=aioredis.Redis,
                                                 **_primary_params(settings), **options)
    return client


def celery_url(settings: Settings) -> str:
    """Celery's broker and result backend URL: redis_url, or one ``sentinel://`` URL per
    sentinel joined by ";" (kombu and Celery try them in turn)."""
    if not settings.redis_sentinels:
        return settings.redis_url
    params = _primary_params(settings)
    auth = ""
    if "password" in params:
        auth = f"{quote(params.get('username', ''), safe='')}:{quote(params['password'], safe='')}@"
    db = params.get("db", 0)
    return ";".join(f"sentinel://{auth}{f'[{h}]' if ':' in h else h}:{p}/{db}"
                    for h, p in sentinel_addresses(settings))


def celery_transport_options(settings: Settings) -> dict[str, Any]:
    """What the broker's and the result backend's transport options need for `celery_url`."""
    if not settings.redis_sentinels:
        return {}
    options: dict[str, Any] = {"master_name": settings.redis_sentinel_master}
    if settings.redis_sentinel_password is not None:
        options["sentinel_kwargs"] = {"password": settings.redis_sentinel_password.get_secret_value()}
    return options

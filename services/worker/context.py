"""The worker process's clients (settings, Redis, job store, object store), made on first use.

Celery's prefork pool forks its children from the main process: sockets and boto3 clients made
before the fork must not be shared with them, so each child drops the ones it inherited.
"""

from __future__ import annotations

import logging
from functools import cache

import redis
from celery.signals import worker_process_init, worker_ready
from prism_common.settings import Settings, get_settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

__all__ = ["link_objects", "objects", "redis_client", "settings", "store"]

log = logging.getLogger(__name__)


def settings() -> Settings:
    return get_settings()


@cache
def redis_client() -> redis.Redis:
    # Timeouts, so a stalled Redis surfaces as an error the task retries, not a hung worker.
    return redis.Redis.from_url(settings().redis_url, decode_responses=True, health_check_interval=30,
                                socket_timeout=30, socket_connect_timeout=5)


@cache
def store() -> JobStore:
    return JobStore(redis_client())


@cache
def objects() -> ObjectStore:
    return ObjectStore.from_settings(settings())


@cache
def link_objects() -> ObjectStore:
    """The bucket at its public endpoint: presigns the links clients download from."""
    return ObjectStore.from_settings(settings(), for_links=True)


@worker_process_init.connect
def _fresh_clients(**_: object) -> None:
    for made in (redis_client, store, objects, link_objects):
        made.cache_clear()


@worker_ready.connect
def _ensure_bucket(**_: object) -> None:
    # Outputs go to the service's bucket: make it if this is a fresh installation. A store that
    # is down now is not fatal: the tasks retry until it is back.
    try:
        objects().ensure_bucket()
    except Exception as exc:
        log.warning("could not check the bucket %r: %s", settings().s3_bucket, exc)

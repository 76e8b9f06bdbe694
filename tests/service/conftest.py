"""Settings, stores and tenants for the service tests, on the session's real Redis and S3
servers (`redis_server`, `s3_server` in tests/conftest.py, shared with the web tests)."""

from __future__ import annotations

import hashlib
import socket
from collections.abc import Iterator

import pytest
import redis
from prism_common.settings import Settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

from .servers import API_KEYS, S3_KEY_ID, S3_SECRET, WEBHOOK_SECRET

__all__ = ["API_KEYS", "WEBHOOK_SECRET"]  # imported from here by the test modules



@pytest.fixture
def settings(redis_server, s3_server, request) -> Settings:
    """Settings pointing at the test servers, with a bucket of the test's own."""
    # A valid, unique S3 bucket name per test, whatever characters the test id holds.
    bucket = "t-" + hashlib.sha256(request.node.nodeid.encode()).hexdigest()[:32]
    return Settings(
        api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET,
        redis_url=f"redis://127.0.0.1:{redis_server.port}/0",
        s3_endpoint_url=f"http://127.0.0.1:{s3_server.port}", s3_bucket=bucket,
        s3_access_key_id=S3_KEY_ID, s3_secret_access_key=S3_SECRET,
        webhook_allowed_hosts=["127.0.0.1"], webhook_allow_private=True,
        # Every test shares these tenants on one Redis: the limit is on (its code runs on every
        # call) but out of reach; the rate-limit tests set their own.
        rate_limit_per_minute=1_000_000, auth_failures_per_minute=1_000_000,
    )


@pytest.fixture
def store(settings) -> JobStore:
    return JobStore(redis.Redis.from_url(settings.redis_url, decode_responses=True))


@pytest.fixture
def objects(settings) -> ObjectStore:
    objects = ObjectStore.from_settings(settings)
    objects.ensure_bucket()
    return objects


@pytest.fixture
def listener() -> Iterator[socket.socket]:
    """A port on 127.0.0.1 that must never see a connection (the SSRF tests point at it)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        sock.setblocking(False)
        yield sock
        with pytest.raises(BlockingIOError):  # nothing is waiting to be accepted
            sock.accept()

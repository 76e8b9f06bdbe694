"""Real Redis and S3 servers for the service tests (started once per session)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator

import pytest
import redis
from prism_common.settings import Settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

from .servers import S3_KEY_ID, S3_SECRET, ManagedProcess, start_redis, start_s3

API_KEYS = {"acme": "key-acme-0123456789abcdef", "globex": "key-globex-0123456789abcdef"}
WEBHOOK_SECRET = "webhook-secret-for-tests"


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory) -> Iterator[ManagedProcess]:
    server = start_redis(tmp_path_factory.mktemp("redis"))
    yield server
    server.stop()


@pytest.fixture(scope="session")
def s3_server(tmp_path_factory) -> Iterator[ManagedProcess]:
    server = start_s3(tmp_path_factory.mktemp("s3"))
    yield server
    server.stop()


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
    )


@pytest.fixture
def store(settings) -> JobStore:
    return JobStore(redis.Redis.from_url(settings.redis_url, decode_responses=True))


@pytest.fixture
def objects(settings) -> ObjectStore:
    objects = ObjectStore.from_settings(settings)
    objects.ensure_bucket()
    return objects

"""The test servers are the ones `prism serve` starts (prism_cli.stack), with test credentials,
and the environment that points a service process (API, worker) at them."""

from __future__ import annotations

import json
from pathlib import Path

from prism_cli.stack import ManagedProcess, free_port, start_redis, wait_for_port
from prism_cli.stack import start_s3 as _start_s3

__all__ = ["API_KEYS", "S3_KEY_ID", "S3_SECRET", "WEBHOOK_SECRET", "ManagedProcess", "free_port",
           "service_env", "start_redis", "start_s3", "wait_for_port"]

S3_KEY_ID = "prism-test-key"
S3_SECRET = "prism-test-secret-0123456789"
API_KEYS = {"acme": "key-acme-0123456789abcdef", "globex": "key-globex-0123456789abcdef"}
WEBHOOK_SECRET = "webhook-secret-for-tests"


def service_env(redis_port: int, s3_port: int, *, db: int, bucket: str, **extra: str) -> dict[str, str]:
    """PRISM_* variables for an API or worker process on Redis database `db` and `bucket` (each
    test module its own, so modules sharing the servers never see each other's jobs); `extra`
    as PRISM_<NAME>=value, e.g. TILES_PER_FACE="4"."""
    return {"PRISM_API_KEYS": json.dumps(API_KEYS), "PRISM_WEBHOOK_SECRET": WEBHOOK_SECRET,
            "PRISM_REDIS_URL": f"redis://127.0.0.1:{redis_port}/{db}",
            "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3_port}", "PRISM_S3_BUCKET": bucket,
            "PRISM_S3_ACCESS_KEY_ID": S3_KEY_ID, "PRISM_S3_SECRET_ACCESS_KEY": S3_SECRET,
            **{f"PRISM_{name}": value for name, value in extra.items()}}


def start_s3(workdir: Path) -> ManagedProcess:
    return _start_s3(workdir, S3_KEY_ID, S3_SECRET)

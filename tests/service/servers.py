"""The test servers are the ones `prism serve` starts (prism_cli.stack), with test credentials."""

from __future__ import annotations

from pathlib import Path

from prism_cli.stack import ManagedProcess, free_port, start_redis, wait_for_port
from prism_cli.stack import start_s3 as _start_s3

__all__ = ["S3_KEY_ID", "S3_SECRET", "ManagedProcess", "free_port", "start_redis", "start_s3",
           "wait_for_port"]

S3_KEY_ID = "prism-test-key"
S3_SECRET = "prism-test-secret-0123456789"


def start_s3(workdir: Path) -> ManagedProcess:
    return _start_s3(workdir, S3_KEY_ID, S3_SECRET)

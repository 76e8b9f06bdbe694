"""Start real servers for the service tests: redis-server and SeaweedFS (S3), on loopback.

Each server gets free ports and its own data folder, and is stopped by the caller. Redis runs
with its append-only file on, as in production, so a restart keeps the job records.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

__all__ = ["ManagedProcess", "free_port", "start_redis", "start_s3", "wait_for_port"]

S3_KEY_ID = "prism-test-key"
S3_SECRET = "prism-test-secret-0123456789"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_port(port: int, timeout: float = 30.0, proc: subprocess.Popen | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"process exited with {proc.returncode} before port {port} opened")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise TimeoutError(f"nothing listening on 127.0.0.1:{port} after {timeout} s")


@dataclass
class ManagedProcess:
    """A server process we started; `restart` keeps its ports and data."""

    argv: list[str]
    port: int
    workdir: Path
    env: dict[str, str] = field(default_factory=dict)
    proc: subprocess.Popen | None = None
    ready_timeout: float = 30.0

    def start(self) -> ManagedProcess:
        with open(self.workdir / "server.log", "ab") as log:  # the child keeps its own copy
            self.proc = subprocess.Popen(self.argv, cwd=self.workdir, stdout=log, stderr=log,
                                         env={**os.environ, **self.env}, start_new_session=True)
        wait_for_port(self.port, self.ready_timeout, self.proc)
        return self

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 15.0) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        os.killpg(self.proc.pid, sig)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def restart(self) -> None:
        self.stop()
        self.start()


def _redis_binary() -> str:
    found = shutil.which("redis-server")
    if found:
        return found
    if sys.platform == "linux" and os.geteuid() == 0 and shutil.which("apt-get"):
        subprocess.run(["apt-get", "update", "-qq"], check=True)
        subprocess.run(["apt-get", "install", "-y", "-qq", "redis-server"], check=True,
                       stdout=subprocess.DEVNULL)
        found = shutil.which("redis-server")
    if not found:
        raise RuntimeError("redis-server is not installed (Debian package redis-server)")
    return found


def start_redis(workdir: Path) -> ManagedProcess:
    port = free_port()
    workdir.mkdir(parents=True, exist_ok=True)
    argv = [_redis_binary(), "--bind", "127.0.0.1", "--port", str(port), "--dir", str(workdir),
            "--appendonly", "yes", "--appendfsync", "everysec", "--save", "",
            "--protected-mode", "yes"]
    return ManagedProcess(argv, port, workdir).start()


def _weed_binary() -> str:
    candidate = Path(sys.executable).with_name("weed")
    return str(candidate) if candidate.exists() else (shutil.which("weed") or "weed")


def start_s3(workdir: Path) -> ManagedProcess:
    """`weed mini` with S3 credentials from AWS_ACCESS_KEY_ID/SECRET: anonymous access refused."""
    workdir.mkdir(parents=True, exist_ok=True)
    ports = {name: free_port() for name in ("s3", "master", "volume", "filer", "admin", "webdav")}
    argv = [_weed_binary(), "mini", f"-dir={workdir}", "-ip=127.0.0.1", "-ip.bind=127.0.0.1"]
    argv += [f"-{name}.port={port}" for name, port in ports.items()]
    proc = ManagedProcess(argv, ports["s3"], workdir, env={
        "AWS_ACCESS_KEY_ID": S3_KEY_ID, "AWS_SECRET_ACCESS_KEY": S3_SECRET}, ready_timeout=60)
    proc.start()
    _wait_s3_ready(ports["s3"])
    return proc


def _wait_s3_ready(port: int, timeout: float = 60.0) -> None:
    # The port opens before the filer behind it is ready; an S3 error reply means it answers.
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/", timeout=2).status_code in (200, 403):
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise TimeoutError("SeaweedFS S3 did not answer")

"""The service on several hosts (netns.py): redis-server, SeaweedFS, the API under uvicorn and two
Celery workers, each process in its own host's namespace and bound to that host's address. The
test itself talks to them from a client host.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import threading
import time
from pathlib import Path

import httpx

from prism_cli.stack import ManagedProcess

from .netns import Network

S3_KEY_ID = "prism-cluster-key"
S3_SECRET = "prism-cluster-secret-0123456789"
API_KEY = "key-cluster-0123456789abcdef"
WEBHOOK_SECRET = "webhook-secret-for-the-cluster"
BUCKET = "cluster"
HOSTS = {"client": 2, "api": 10, "w1": 21, "w2": 22, "redis": 30, "store": 40}
REDIS_PORT, S3_PORT, API_PORT, HOOK_PORT = 6379, 8333, 8000, 9000
# Shorter than the defaults so faults heal in a minute or two, in the same order: a task's time
# limit (plus margin) under the visibility timeout, and above how long a request to a store that
# drops packets for 30 s can hang (TCP retransmits, backing off, reach it up to ~50 s after the
# cut; with a 45 s limit, tasks did hit it).
SETTINGS = {"VISIBILITY_TIMEOUT_S": "90", "TASK_TIME_LIMIT_S": "70", "TASK_HARD_MARGIN_S": "10",
            "WATCHDOG_INTERVAL_S": "2", "JOB_STALL_TIMEOUT_S": "15", "JOB_STALL_RESTARTS": "3",
            "TILES_PER_FACE": "2", "ITEMS_IN_FLIGHT_PER_JOB": "2"}


def wait_port(address: str, port: int, proc: ManagedProcess, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.proc is not None and proc.proc.poll() is None, proc.log[-3000:]
        with socket.socket() as s:
            s.settimeout(1)
            if s.connect_ex((address, port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError(f"nothing on {address}:{port} after {timeout} s:\n{proc.log[-3000:]}")


class Cluster:
    """Every host's processes; call from inside the client host (netns.inside)."""

    def __init__(self, net: Network, workdir: Path) -> None:
        self.net, self.workdir = net, workdir
        redis_url = f"redis://{net.addr('redis')}:{REDIS_PORT}/0"
        self.store_url = f"http://{net.addr('store')}:{S3_PORT}"
        self.api_url = f"http://{net.addr('api')}:{API_PORT}"
        self.hook_url = f"http://{net.addr('client')}:{HOOK_PORT}/hook"
        self.env = {
            "PRISM_API_KEYS": json.dumps({"acme": API_KEY}), "PRISM_WEBHOOK_SECRET": WEBHOOK_SECRET,
            "PRISM_REDIS_URL": redis_url, "PRISM_S3_ENDPOINT_URL": self.store_url,
            "PRISM_S3_BUCKET": BUCKET, "PRISM_S3_ACCESS_KEY_ID": S3_KEY_ID,
            "PRISM_S3_SECRET_ACCESS_KEY": S3_SECRET,
            "PRISM_WEBHOOK_ALLOWED_HOSTS": json.dumps([net.addr("client")]),
            "PRISM_WEBHOOK_ALLOW_HTTP": "true", "PRISM_WEBHOOK_ALLOW_PRIVATE": "true",
            **{f"PRISM_{k}": v for k, v in SETTINGS.items()}}
        self.redis = self._process("redis", [
            "redis-server", "--bind", net.addr("redis"), "--port", str(REDIS_PORT),
            "--dir", str(workdir / "redis"), "--appendonly", "yes", "--appendfsync", "everysec",
            "--save", "", "--protected-mode", "no"])
        self.store = self._process("store", [
            str(Path(sys.executable).with_name("weed")), "mini", f"-dir={workdir / 'store'}",
            f"-ip={net.addr('store')}", f"-ip.bind={net.addr('store')}", f"-s3.port={S3_PORT}"],
            env={"AWS_ACCESS_KEY_ID": S3_KEY_ID, "AWS_SECRET_ACCESS_KEY": S3_SECRET})
        self.api = self._process("api", [
            sys.executable, "-m", "uvicorn", "prism_api.main:app", "--host", net.addr("api"),
            "--port", str(API_PORT), "--no-access-log"], env=self.env)
        self.workers = {host: self._process(host, [
            sys.executable, "-m", "celery", "-A", "prism_worker.app", "worker",
            "-Q", "scans,frames,webhooks", "--concurrency", "2", "--loglevel", "info",
            "--hostname", f"{host}@%h", "--without-gossip", "--without-mingle"], env=self.env)
            for host in ("w1", "w2")}

    def supervise(self) -> None:
        """Start a worker again when it exits by itself, as the deployment's restart policy
        does (docker-compose: `restart: unless-stopped`); hosts in `down` are left down."""
        self.down: set[str] = set()
        self.restarts = 0
        self._supervising = threading.Event()
        self._supervising.set()

        def loop() -> None:
            while self._supervising.is_set():
                for host, worker in self.workers.items():
                    if host not in self.down and worker.proc is not None and worker.proc.poll() is not None:
                        self.restarts += 1
                        worker.start()
                time.sleep(1)

        self._supervisor = threading.Thread(target=loop, daemon=True)
        self._supervisor.start()

    def _process(self, host: str, argv: list[str], env: dict[str, str] | None = None) -> ManagedProcess:
        (self.workdir / host).mkdir(parents=True, exist_ok=True)
        return ManagedProcess(self.net.exec_argv(host, argv), None, self.workdir / host, env=env or {})

    @property
    def processes(self) -> list[ManagedProcess]:
        return [*self.workers.values(), self.api, self.store, self.redis]

    def start(self) -> None:
        self.start_redis()
        self.store.start()
        deadline = time.monotonic() + 90
        while True:  # the S3 port opens before the gateway answers
            try:
                if httpx.get(self.store_url + "/", timeout=2).status_code in (200, 403):
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline and self.store.proc.poll() is None, self.store.log[-3000:]
            time.sleep(0.3)
        self.start_api()
        for host in self.workers:
            self.start_worker(host)
        self.supervise()

    def start_redis(self) -> None:
        self.redis.start()
        wait_port(self.net.addr("redis"), REDIS_PORT, self.redis)

    def start_api(self) -> None:
        self.api.start()
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(self.api_url + "/healthz", timeout=2).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline and self.api.proc.poll() is None, self.api.log[-3000:]
            time.sleep(0.2)

    def start_worker(self, host: str, timeout: float = 90) -> None:
        worker = self.workers[host]
        readies = worker.log.count(" ready.")
        worker.start()
        deadline = time.monotonic() + timeout
        while worker.log.count(" ready.") <= readies:
            assert worker.proc is not None and worker.proc.poll() is None, worker.log[-3000:]
            assert time.monotonic() < deadline, f"{host} not ready:\n{worker.log[-3000:]}"
            time.sleep(0.2)

    def stop(self) -> None:
        if getattr(self, "_supervisor", None) is not None:
            self._supervising.clear()
            self._supervisor.join(10)
        for process in self.processes:
            with contextlib.suppress(ProcessLookupError, OSError):
                process.stop(timeout=15)

    def logs(self) -> str:
        return "\n".join(f"--- {os.path.basename(p.workdir)}\n{p.log[-2500:]}" for p in self.processes)

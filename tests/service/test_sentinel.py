"""Redis behind Sentinel, on loopback: a primary, a replica and three sentinels started here,
the API and two workers configured with PRISM_REDIS_SENTINELS. Jobs stream in; the primary is
SIGKILLed; the sentinels promote the replica; the API answers again, the workers finish the
jobs, and every job answered with a 2xx ends (none lost, none made twice).
"""

from __future__ import annotations

import shutil
import threading
import time
import uuid
from pathlib import Path

import httpx
import pytest
import redis

from prism_cli.stack import ManagedProcess, free_ports, start_api, start_worker
from prismsynth import Box, render_oblique_view

from .faultstack import BUCKET, FaultStack, item, png
from .servers import service_env, start_s3

MASTER = "prism"
JOBS = 12
KILL_AFTER = 4  # jobs submitted before the test looks for one running, to kill the primary
MAX_JOBS = 60  # ends the submitting if no job is ever seen running
SUBMIT_EVERY_S = 0.7


def _redis(workdir: Path, port: int, *extra: str) -> ManagedProcess:
    argv = ["redis-server", "--bind", "127.0.0.1", "--port", str(port), "--dir", str(workdir),
            "--appendonly", "yes", "--appendfsync", "everysec", "--save", "", *extra]
    return ManagedProcess(argv, port, workdir).start()


def _sentinel(workdir: Path, port: int, primary_port: int) -> ManagedProcess:
    workdir.mkdir(parents=True, exist_ok=True)
    conf = workdir / "sentinel.conf"  # sentinels rewrite their file: one each
    conf.write_text(f"port {port}\nbind 127.0.0.1\ndir {workdir}\n"
                    f"sentinel monitor {MASTER} 127.0.0.1 {primary_port} 2\n"
                    f"sentinel down-after-milliseconds {MASTER} 1000\n"
                    # A failed election (a split vote under load) is retried after twice this:
                    # 10 s here kept a loaded CI machine without a primary for over a minute.
                    f"sentinel failover-timeout {MASTER} 4000\n"
                    f"sentinel parallel-syncs {MASTER} 1\n")
    binary = shutil.which("redis-sentinel")
    argv = [binary, str(conf)] if binary else ["redis-server", str(conf), "--sentinel"]
    return ManagedProcess(argv, port, workdir).start()


class SentinelStack(FaultStack):
    """FaultStack's client side (submit, wait, audits) on a Sentinel-managed Redis."""

    def __init__(self, workdir: Path) -> None:  # FaultStack's servers, but Redis's differ
        self.workdir = workdir
        primary, replica, *sentinels = free_ports(5)
        self.primary = _redis(workdir / "primary", primary)
        self.replica = _redis(workdir / "replica", replica, "--replicaof", "127.0.0.1", str(primary))
        self.sentinel_ports = sentinels
        self.sentinels = [_sentinel(workdir / f"sentinel{i}", port, primary)
                          for i, port in enumerate(sentinels)]
        self.redis = self.primary
        self.s3 = start_s3(workdir / "s3")
        self.env = service_env(primary, self.s3.port, db=0, bucket=BUCKET,
                               VISIBILITY_TIMEOUT_S="20", WATCHDOG_INTERVAL_S="2",
                               JOB_STALL_TIMEOUT_S="15", JOB_STALL_RESTARTS="3",
                               REDIS_SENTINELS=",".join(f"127.0.0.1:{p}" for p in sentinels),
                               REDIS_SENTINEL_MASTER=MASTER)
        self._wait_replicated()
        self.api = start_api(workdir / "api", self.env)
        self.workers = [start_worker(workdir / f"worker{i}", self.env, 1, name=f"w{i}") for i in range(2)]
        self.http = httpx.Client(base_url=f"http://127.0.0.1:{self.api.port}", timeout=30)
        for worker in self.workers:
            self.wait_ready(worker, 0)

    @property
    def processes(self) -> list[ManagedProcess]:
        return [*self.workers, self.api, self.s3, *self.sentinels, self.replica, self.primary]

    def _wait_replicated(self, timeout: float = 60) -> None:
        """The replica in sync and every sentinel aware of it and of the others."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                link = redis.Redis(port=self.replica.port).info("replication").get("master_link_status")
                views = [redis.Redis(port=p, socket_timeout=2).sentinel_master(MASTER)
                         for p in self.sentinel_ports]
                if link == "up" and all(v["num-slaves"] >= 1 and v["num-other-sentinels"] >= 2
                                        for v in views):
                    return
            except redis.RedisError:
                pass
            assert time.monotonic() < deadline, "sentinels never saw the replica and each other"
            time.sleep(0.2)

    def primary_port(self) -> int:
        """Where the sentinels say the primary is (the first sentinel that answers)."""
        for port in self.sentinel_ports:
            try:
                _, primary = redis.Redis(port=port, socket_timeout=2).sentinel_get_master_addr_by_name(MASTER)
                return int(primary)
            except (redis.RedisError, TypeError):
                continue
        raise AssertionError("no sentinel answers")

    def sentinel_logs(self, tail: int = 1500) -> str:
        """The end of each sentinel's log and the replica's: what an assertion shows."""
        return "\n".join(f"--- {p.workdir.name}:\n{p.log[-tail:]}" for p in [*self.sentinels, self.replica])

    def redis_client(self) -> redis.Redis:
        return redis.Redis(port=self.primary_port(), decode_responses=True, socket_timeout=10)


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    stack = SentinelStack(tmp_path_factory.mktemp("sentinel"))
    yield stack
    stack.stop()


def test_primary_killed_with_jobs_in_flight_sentinel_promotes_and_nothing_is_lost(stack, figures):
    scene = render_oblique_view(Box(120.0, 80.0, 60.0), image_size=(640, 512), focal_px=700.0, seed=5)
    ref = stack.upload(png(scene.image))
    spec = item(ref, scene)
    accepted: dict[str, str] = {}  # Idempotency-Key -> job id, for every 2xx
    first_after_kill: list[float] = []
    killed_at: list[float] = []
    started = threading.Event()
    errors: list[BaseException] = []

    def submit_all() -> None:
        try:
            submit_jobs()
        except BaseException as exc:  # reported by the test, with the sentinels' logs
            errors.append(exc)
            started.set()

    def submit_jobs() -> None:
        # Submitting goes on until the kill: a pause there let a fast machine finish every
        # job before the test saw one running, and it then waited for one that never came.
        after_kill = 0
        while after_kill < JOBS - KILL_AFTER and len(accepted) < MAX_JOBS:
            if len(accepted) == KILL_AFTER:
                started.set()
            key = uuid.uuid4().hex
            killed_before = bool(killed_at)
            accepted[key] = stack.submit([spec, spec], key=key)  # retries 503s and refusals
            if killed_at and not first_after_kill:
                first_after_kill.append(time.monotonic() - killed_at[0])
            after_kill += killed_before
            time.sleep(SUBMIT_EVERY_S)

    submitter = threading.Thread(target=submit_all)
    submitter.start()
    assert started.wait(60) and not errors, errors
    client = stack.redis_client()
    deadline = time.monotonic() + 60
    while not client.zcard("prism:state:running"):  # jobs in flight, not only queued
        assert time.monotonic() < deadline
        time.sleep(0.02)
    client.close()
    old = stack.primary.port
    stack.primary.kill()
    killed_at.append(time.monotonic())
    while stack.primary_port() == old:
        assert time.monotonic() - killed_at[0] < 60, f"no failover within 60 s\n{stack.sentinel_logs()}"
        time.sleep(0.05)
    promoted_s = time.monotonic() - killed_at[0]
    submitter.join(timeout=300)
    assert not submitter.is_alive() and not errors, (errors, stack.sentinel_logs())
    assert stack.primary_port() == stack.replica.port

    jobs = stack.wait(list(accepted.values()), timeout=300)
    ready = stack.ready()
    states = [j["state"] for j in jobs.values()]
    lost = sum(s != "succeeded" for s in states)
    client = stack.redis_client()
    stored = set()
    for state in ("queued", "running", "succeeded", "completed_with_failures", "failed", "cancelled"):
        stored |= set(client.zrange(f"prism:state:{state}", 0, -1))
    duplicated = len(stored - set(accepted.values()))
    counted_twice = [j for j in accepted.values()
                     if int(client.hget(f"prism:job:{j}", "items_done") or 0) != 2]
    print(f"\nsentinel failover: primary SIGKILLed with jobs in flight; replica promoted "
          f"{promoted_s:.1f} s later; first submit answered {first_after_kill[0]:.1f} s after the kill; "
          f"jobs {len(accepted)} (2 items each), succeeded {states.count('succeeded')}, lost {lost}, "
          f"duplicated {duplicated}; /readyz {ready[0]}")
    assert lost == 0 and duplicated == 0 and not counted_twice, (states, stored, counted_twice)
    assert ready[0] == 200
    for worker in stack.workers:  # rode the failover out in the same process
        assert worker.proc is not None and worker.proc.poll() is None, worker.log[-3000:]
        log = worker.log
        assert log.count(" ready.") == 1 and "Unrecoverable error" not in log, log[-3000:]
    for job_id in accepted.values():
        assert {"items/0/cloud.ply", "items/1/cloud.ply"} <= stack.keys(job_id)  # the default cloud
    figures.update({"faults survived": 1, "jobs submitted": len(accepted),
                    "jobs succeeded": states.count("succeeded")})


def test_sentinel_settings_and_celery_urls(monkeypatch):
    from prism_common.redis_client import celery_transport_options, celery_url
    from prism_common.settings import Settings
    from pydantic import ValidationError

    from .conftest import API_KEYS, WEBHOOK_SECRET

    base = {"api_keys": API_KEYS, "webhook_secret": WEBHOOK_SECRET}
    monkeypatch.setenv("PRISM_REDIS_SENTINELS", " 10.0.0.1:26379,redis-b:26380 ")
    monkeypatch.setenv("PRISM_REDIS_URL", "redis://:p%40ss@ignored:6379/3")
    monkeypatch.setenv("PRISM_REDIS_SENTINEL_PASSWORD", "s3")
    settings = Settings(**base)
    assert settings.redis_sentinels == ["10.0.0.1:26379", "redis-b:26380"]
    assert celery_url(settings) == "sentinel://:p%40ss@10.0.0.1:26379/3;sentinel://:p%40ss@redis-b:26380/3"
    assert celery_transport_options(settings) == {"master_name": "prism",
                                                  "sentinel_kwargs": {"password": "s3"}}
    monkeypatch.setenv("PRISM_REDIS_SENTINELS", "10.0.0.1")
    with pytest.raises(ValidationError, match="is not host:port"):
        Settings(**base)
    monkeypatch.delenv("PRISM_REDIS_SENTINELS")
    plain = Settings(**base)
    assert celery_url(plain) == plain.redis_url and celery_transport_options(plain) == {}

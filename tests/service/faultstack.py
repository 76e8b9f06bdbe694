"""A whole service of its own for tests that break things: redis-server, SeaweedFS, Celery
workers and the API under uvicorn, all on loopback, none shared with other test modules (they
are stopped, killed and restarted here).
"""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import httpx
import numpy as np
import redis
from prism_common.settings import Settings
from prism_common.storage import ObjectStore

from prism_cli.stack import ManagedProcess, start_api, start_redis, start_s3, start_worker
from prismsynth import Box, Scene, render_oblique_view

from .conftest import API_KEYS, WEBHOOK_SECRET
from .servers import S3_KEY_ID, S3_SECRET, service_env

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
FINAL = ("succeeded", "completed_with_failures", "failed", "cancelled")
BUCKET = "faults"


def tiny_scene(seed: int = 1) -> Scene:
    """A 160x128 render: a scan in a few ms, so a test can run a thousand."""
    return render_oblique_view(Box(120.0, 80.0, 60.0), image_size=(160, 128), focal_px=175.0, seed=seed)


def png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    assert ok
    return data.tobytes()


def item(reference: str, scene: Scene, **extra) -> dict:
    return {"image": reference, "points": [list(map(round, scene.points[n])) for n in NAMES],
            "focal_px": scene.focal_px, "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm},
            **extra}


class FaultStack:
    def __init__(self, workdir: Path, workers: int = 1, concurrency: int = 2, **settings: str) -> None:
        self.workdir = workdir
        self.redis = start_redis(workdir / "redis")
        self.s3 = start_s3(workdir / "s3", S3_KEY_ID, S3_SECRET)
        defaults = {"VISIBILITY_TIMEOUT_S": "10", "WATCHDOG_INTERVAL_S": "2",
                    "JOB_STALL_TIMEOUT_S": "15", "JOB_STALL_RESTARTS": "3"}
        self.env = service_env(self.redis.port, self.s3.port, db=0, bucket=BUCKET, **defaults)
        self.env.update(settings)  # PRISM_* names as given
        self.api = start_api(workdir / "api", self.env)
        self.workers = [start_worker(workdir / f"worker{i}", self.env, concurrency, name=f"w{i}")
                        for i in range(workers)]
        self.http = httpx.Client(base_url=f"http://127.0.0.1:{self.api.port}", timeout=30)
        for worker in self.workers:
            self.wait_ready(worker, 0)

    @property
    def processes(self) -> list[ManagedProcess]:
        return [*self.workers, self.api, self.s3, self.redis]

    def stop(self) -> None:
        self.http.close()
        for process in self.processes:
            process.stop()

    @staticmethod
    def wait_ready(worker: ManagedProcess, readies_before: int, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while worker.log.count(" ready.") <= readies_before:
            assert worker.proc is not None and worker.proc.poll() is None, worker.log[-3000:]
            assert time.monotonic() < deadline, f"worker not ready:\n{worker.log[-3000:]}"
            time.sleep(0.1)

    def restart_worker(self, worker: ManagedProcess, *, kill: bool = True) -> None:
        readies = worker.log.count(" ready.")
        worker.kill() if kill else worker.stop()
        worker.start()
        self.wait_ready(worker, readies)

    def call(self, method: str, path: str, *, tries: int = 60, **kwargs) -> httpx.Response:
        """A client that rides out a restarting API or backend: retries connection errors and
        503s (the caller's Idempotency-Key makes a retried submit safe)."""
        headers = {"X-API-Key": API_KEYS["acme"], **kwargs.pop("headers", {})}
        for _ in range(tries):
            try:
                r = self.http.request(method, path, headers=headers, **kwargs)
            except httpx.TransportError:
                time.sleep(0.5)
                continue
            if r.status_code != 503:
                return r
            time.sleep(0.5)
        raise AssertionError(f"{method} {path}: no answer after {tries} tries")

    def upload(self, data: bytes, name: str = "box.png", tenant: str = "acme") -> str:
        r = self.call("POST", "/v1/uploads", files={"file": (name, data)},
                      headers={"X-API-Key": API_KEYS[tenant]})
        assert r.status_code in (200, 201), r.text  # 200: the same content again
        return r.json()["reference"]

    def submit(self, items: list[dict], key: str | None = None, **extra) -> str:
        headers = {"Idempotency-Key": key} if key else {}
        r = self.call("POST", "/v1/jobs", json={"items": items, **extra}, headers=headers)
        assert r.status_code == 202, r.text
        return r.json()["id"]

    def job(self, job_id: str) -> dict:
        r = self.call("GET", f"/v1/jobs/{job_id}")
        assert r.status_code == 200, r.text
        return r.json()

    def wait(self, job_ids: list[str], timeout: float = 180) -> dict[str, dict]:
        """Every job's final state; fails naming the ones still unfinished after `timeout` s."""
        deadline, final = time.monotonic() + timeout, {}
        while True:
            for job_id in job_ids:
                if job_id not in final and (job := self.job(job_id))["state"] in FINAL:
                    final[job_id] = job
            if len(final) == len(job_ids):
                return final
            if time.monotonic() > deadline:
                left = [self.job(j) for j in job_ids if j not in final][:3]
                raise AssertionError(f"{len(job_ids) - len(final)} jobs not final after {timeout} s: "
                                     f"{left}\n{self.workers[0].log[-3000:]}")
            time.sleep(0.5)

    def objects(self) -> ObjectStore:
        return ObjectStore.from_settings(Settings(
            api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET,
            s3_endpoint_url=self.env["PRISM_S3_ENDPOINT_URL"], s3_bucket=BUCKET,
            s3_access_key_id=S3_KEY_ID, s3_secret_access_key=S3_SECRET))

    def redis_client(self) -> redis.Redis:
        return redis.Redis(port=self.redis.port, decode_responses=True, socket_timeout=10)

    def keys(self, job_id: str) -> set[str]:
        prefix = f"jobs/{job_id}/"
        return {k.removeprefix(prefix) for k in self.objects().list_keys(prefix)}

    def ready(self) -> tuple[int, dict]:
        """/readyz's status and each backend's state (a 503 is a problem document whose
        `checks` hold them)."""
        r = self.http.get("/readyz", timeout=10)
        body = r.json()
        return r.status_code, body["checks"] if r.status_code == 503 else body

"""A real `celery worker` process (2 prefork children) on the test Redis and SeaweedFS, and the
client side the tests drive it with: the job store, the bucket, a Celery app that sends tasks.
"""

from __future__ import annotations

import json
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np
import redis
from celery import Celery
from prism_common.metrics import read_task_durations
from prism_common.queue import TASK_RUN_JOB, WORKER_QUEUES, make_celery
from prism_common.records import FINAL_STATES, ItemRecord, JobRecord
from prism_common.settings import Settings
from prism_common.storage import ObjectStore, object_key
from prism_common.store import JobStore

from prism_worker.broker import pending_job_ids
from prismcore import ScanSpec

from .conftest import API_KEYS, WEBHOOK_SECRET
from .servers import S3_KEY_ID, S3_SECRET, ManagedProcess, service_env

INPUTS_BUCKET = "t-worker-inputs"
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


class Env:
    """What the tests drive the worker with: the store, the bucket, a client Celery app."""

    def __init__(self, settings: Settings, worker: ManagedProcess) -> None:
        self.settings, self.worker = settings, worker
        self.redis = redis.Redis.from_url(settings.redis_url, decode_responses=True)
        self.store = JobStore(self.redis)
        self.objects = ObjectStore.from_settings(settings)
        self.celery: Celery = make_celery(settings)

    def upload(self, data: bytes, name: str = "box.png", tenant: str = "acme") -> str:
        upload_id = uuid.uuid4().hex
        key = object_key("uploads", tenant, upload_id)
        self.objects.put_bytes(key, data)
        self.store.put_upload(upload_id, tenant=tenant, key=key, size=len(data), name=name)
        return f"upload:{upload_id}"

    def create(self, specs: list[ScanSpec], **extra) -> str:
        job = JobRecord(id=uuid.uuid4().hex, tenant="acme", created_at=datetime.now(UTC),
                        items=[ItemRecord(index=i, spec=s) for i, s in enumerate(specs)], **extra)
        self.store.create(job)
        return job.id

    def submit(self, specs: list[ScanSpec], **extra) -> str:
        job_id = self.create(specs, **extra)
        self.celery.send_task(TASK_RUN_JOB, (job_id,))
        return job_id

    def wait(self, job_id: str, timeout: float = 60) -> JobRecord:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            job = self.store.get(job_id)
            if job is not None and job.state in FINAL_STATES:
                # The job ends, then job.json is written (lifecycle: state first, manifest
                # after): give the manifest a moment so that the tests listing a job's keys
                # do not race it (a full run at idle once listed them in between).
                settle = time.monotonic() + 30
                while "job.json" not in self.keys(job_id) and time.monotonic() < settle:
                    time.sleep(0.1)
                return job
            time.sleep(0.1)
        raise AssertionError(f"job {job_id} not final after {timeout} s: {job}\n{self.worker.log[-4000:]}")

    def keys(self, job_id: str) -> set[str]:
        prefix = f"jobs/{job_id}/"
        return {k.removeprefix(prefix) for k in self.objects.list_keys(prefix)}

    def units(self, job_id: str) -> tuple[int, int]:
        fields = self.redis.hmget(f"prism:job:{job_id}", "units_total", "units_done")
        return int(fields[0]), int(fields[1])

    def runs(self, task: str) -> int:
        return int(read_task_durations(self.redis).get(task, {}).get("count", 0))

    def wait_no_task(self, job_id: str, timeout: float = 60) -> None:
        wait_no_task(self.redis, job_id, timeout)


def wait_no_task(client: redis.Redis, job_id: str, timeout: float = 60) -> None:
    """Until no task of the job is queued, running or due for a retry (the broker's lists and
    its unacked hash, as the watchdog reads them), on two looks in a row: a task between its
    queue and the unacked hash is in neither for a moment. What a fixed pause assumed (the
    redelivered copies or the tasks in flight at a cancel have run out) is waited for."""
    deadline = time.monotonic() + timeout
    quiet = 0
    while True:
        quiet = quiet + 1 if job_id not in pending_job_ids(client) else 0
        if quiet == 2:
            return
        assert time.monotonic() < deadline, f"job {job_id} still has tasks after {timeout} s"
        time.sleep(0.2)


@contextmanager
def worker_env(redis_server: ManagedProcess, s3_server: ManagedProcess, workdir: Path, *, db: int,
               bucket: str, tiles_per_face: int, items_in_flight: int,
               max_frames: int = 1000, stall_timeout_s: int = 600, visibility_timeout_s: int = 10,
               extra_env: dict[str, str] | None = None) -> Iterator[Env]:
    """Start a worker with these settings on Redis database `db` and `bucket`; stop it after.
    `extra_env`: more PRISM_<NAME> settings for the worker process only, e.g. FETCH_CA_BUNDLE.
    `visibility_timeout_s`: short, so a lost task comes back quickly; a task that runs longer is
    handed out a second time meanwhile (idempotent, but twice the work)."""
    settings = Settings(
        api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET,
        redis_url=f"redis://127.0.0.1:{redis_server.port}/{db}",
        s3_endpoint_url=f"http://127.0.0.1:{s3_server.port}", s3_bucket=bucket,
        s3_access_key_id=S3_KEY_ID, s3_secret_access_key=S3_SECRET,
        readable_buckets=[INPUTS_BUCKET], webhook_allowed_hosts=["127.0.0.1"],
        webhook_allow_private=True, tiles_per_face=tiles_per_face,
        items_in_flight_per_job=items_in_flight, visibility_timeout_s=visibility_timeout_s,
        max_frames_per_job=max_frames, job_stall_timeout_s=stall_timeout_s,
        watchdog_interval_s=min(30, max(1, stall_timeout_s // 4)))
    variables = service_env(
        redis_server.port, s3_server.port, db=db, bucket=bucket,
        READABLE_BUCKETS=json.dumps([INPUTS_BUCKET]), WEBHOOK_ALLOWED_HOSTS='["127.0.0.1"]',
        WEBHOOK_ALLOW_PRIVATE="true", TILES_PER_FACE=str(tiles_per_face),
        VISIBILITY_TIMEOUT_S=str(visibility_timeout_s),
        ITEMS_IN_FLIGHT_PER_JOB=str(items_in_flight), MAX_FRAMES_PER_JOB=str(max_frames),
        JOB_STALL_TIMEOUT_S=str(settings.job_stall_timeout_s),
        WATCHDOG_INTERVAL_S=str(settings.watchdog_interval_s), **(extra_env or {}))
    objects = ObjectStore.from_settings(settings)
    objects.ensure_bucket()
    ObjectStore(objects.client, INPUTS_BUCKET).ensure_bucket()
    argv = [sys.executable, "-m", "celery", "-A", "prism_worker.app", "worker", "-Q",
            WORKER_QUEUES, "--concurrency", "2", "--pool", "prefork", "-l", "info",
            "--hostname", f"test-worker-{db}@%h", "--without-gossip", "--without-mingle"]
    worker = ManagedProcess(argv, None, workdir, env=variables).start()
    env = Env(settings, worker)
    try:
        deadline = time.monotonic() + 60
        while " ready." not in worker.log:
            assert worker.proc is not None and worker.proc.poll() is None, worker.log[-4000:]
            assert time.monotonic() < deadline, f"worker not ready:\n{worker.log[-4000:]}"
            time.sleep(0.1)
        yield env
    finally:
        worker.stop()
        env.celery.close()
    assert "could not record" not in worker.log, worker.log[-4000:]


def encode(image: np.ndarray, ext: str = ".png") -> bytes:
    ok, data = cv2.imencode(ext, cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    assert ok
    return data.tobytes()


def spec_for(reference: str, scene, **extra) -> ScanSpec:
    return ScanSpec.model_validate({
        "image": reference, "points": [list(map(round, scene.points[n])) for n in NAMES],
        "focal_px": scene.focal_px, "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm},
        **extra})


DEFAULT_SPACING_MM = Settings.model_fields["default_spacing_mm"].default


def as_stored(item: dict) -> ScanSpec:
    """The item's spec as the API stores it when no PRISM_DEFAULT_SPACING_MM is set: an item with
    a scale and no spacing of its own gets the service's default spacing (routes/jobs._spacing)."""
    if "spacing_mm" not in item and ("scale" in item or "station" in item):
        item = {**item, "spacing_mm": DEFAULT_SPACING_MM}
    return ScanSpec.model_validate(item)

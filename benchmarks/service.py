"""Service benchmark: photos through the real stack against the engine alone, side by side.

Starts redis-server, SeaweedFS, a Celery worker (2 processes) and the API on loopback, uploads
N photos of 1280x1024, submits them as jobs at a steady rate, and prints:
* images per second end to end (first submit to last job final) and for the engine alone on
  the same images with the same number of processes (decode, scan, CSV + PLY into memory);
  their ratio shows the service's overhead (target >= 0.7 with 2 processes on 2 cores);
* the engine again, storing the same outputs (CSV, PLY, preview, report) into the same
  SeaweedFS with boto3, no queue: the share of the overhead that is object storage itself
  (on this machine the store's server shares the 2 cores with the workers);
* submit latency p50/p99 at the steady request rate, and status-poll latency p50/p99;
* then the same photos again through the same service for each output mode, side by side:
  CSV + PLY, compact (LAZ + glb: the service's default for items with a scale, as these have)
  and compact at a 1 mm spacing: images per second and
  the bytes stored per photo (every object under the jobs' prefixes: the formats, preview.ply,
  overlay.png, report.json, job.json), against the issue's ceiling of 4 MB for compact.

Run: .venv/bin/python benchmarks/service.py [--images 200] [--per-job 10] [--rate 20]
"""

from __future__ import annotations

import argparse
import io
import json
import secrets
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import boto3
import cv2
import httpx
import numpy as np
from botocore.client import Config
from rich.console import Console
from rich.table import Table

from prism_cli.stack import start_api, start_redis, start_s3, start_worker
from prismcore import ScanSpec, run_scan
from prismcore.io.images import load_image
from prismcore.outputs.writers import write_csv, write_ply
from prismcore.report import report_dict
from prismcore.scan.cloud import decimate
from prismsynth import Box, render_oblique_view

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
PROCESSES = 2
STORE_BUCKET = "bench-engine"
SERVICE_BUCKET = "prismcloud"  # the service's default bucket
# Output modes: what each item of a run adds to its spec.
# The first is the one compared with the engine alone (which writes CSV and PLY too).
MODES = {"csv + ply": {"formats": ["csv", "ply"]},
         "compact (laz + glb, the default)": {},
         "compact, 1 mm spacing": {"spacing_mm": 1.0}}
COMPACT_MAX_BYTES = 4_000_000


def _scenes(count: int) -> list[tuple[bytes, dict]]:
    out = []
    for seed in range(count):
        box = Box(80 + 20 * (seed % 4), 60 + 15 * (seed % 3), 40 + 10 * (seed % 5))
        scene = render_oblique_view(box, seed=seed)
        _, jpeg = cv2.imencode(".jpg", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, 90])
        item = {"points": [list(map(round, scene.points[n])) for n in NAMES],
                "focal_px": scene.focal_px,
                "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}}
        out.append((jpeg.tobytes(), item))
    return out


def _engine_one(args: tuple[bytes, dict]) -> int:
    data, item = args
    result = run_scan(ScanSpec.model_validate({"image": "x", **item}), load_image(data))
    write_csv(io.BytesIO(), result.cloud.points)
    write_ply(io.BytesIO(), result.cloud.points, result.cloud.colors)
    return result.report.points or 0


_STORE: list = []  # the boto3 client of an engine-and-store process


def _store_init(endpoint: str, key_id: str, secret: str) -> None:
    _STORE.append(boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1",
                               aws_access_key_id=key_id, aws_secret_access_key=secret,
                               config=Config(signature_version="s3v4",
                                             s3={"addressing_style": "path"})))


def _engine_and_store_one(args: tuple[int, bytes, dict]) -> int:
    n, data, item = args
    result = run_scan(ScanSpec.model_validate({"image": "x", **item}), load_image(data))
    preview = decimate(result.cloud)
    for name, write in (("cloud.csv", lambda f: write_csv(f, result.cloud.points)),
                        ("cloud.ply", lambda f: write_ply(f, result.cloud.points, result.cloud.colors)),
                        ("preview.ply", lambda f: write_ply(f, preview.points, preview.colors)),
                        ("report.json", lambda f: f.write(json.dumps(report_dict(result.report)).encode()))):
        body = io.BytesIO()
        write(body)
        body.seek(0)
        _STORE[0].put_object(Bucket=STORE_BUCKET, Key=f"engine/{n}/{name}", Body=body)
    return result.report.points or 0


def engine_alone(work: list[tuple[bytes, dict]], store: tuple[str, str, str] | None = None) -> float:
    """Images per second with PROCESSES engine processes, no queue; with `store` (endpoint,
    key id, secret) each process also puts its outputs into that S3 store."""
    one, init = (_engine_one, None) if store is None else (_engine_and_store_one, _store_init)
    jobs = list(work) if store is None else [(n, *w) for n, w in enumerate(work)]
    with ProcessPoolExecutor(PROCESSES, initializer=init, initargs=store or ()) as pool:
        list(pool.map(one, jobs[:PROCESSES]))  # warm the processes up
        start = time.perf_counter()
        list(pool.map(one, jobs))
        return len(work) / (time.perf_counter() - start)


def through_service(work: list[tuple[bytes, dict]], per_job: int, rate: float, tmp: Path) -> dict:
    key = secrets.token_urlsafe(16)
    creds = ("bench-key", "bench-secret-" + secrets.token_hex(8))
    redis = start_redis(tmp / "redis")
    s3 = start_s3(tmp / "s3", *creds)
    try:
        endpoint = f"http://127.0.0.1:{s3.port}"
        _store_init(endpoint, *creds)
        _STORE.pop().create_bucket(Bucket=STORE_BUCKET)
        engine_store_rate = engine_alone(work, (endpoint, *creds))
    except BaseException:
        s3.stop()
        redis.stop()
        raise
    env = {"PRISM_API_KEYS": json.dumps({"bench": key}), "PRISM_WEBHOOK_SECRET": "x" * 16,
           "PRISM_REDIS_URL": f"redis://127.0.0.1:{redis.port}/0",
           "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3.port}",
           "PRISM_S3_ACCESS_KEY_ID": creds[0], "PRISM_S3_SECRET_ACCESS_KEY": creds[1]}
    procs = [redis, s3, start_api(tmp / "api", env), start_worker(tmp / "w", env, PROCESSES)]
    try:
        http = httpx.Client(base_url=f"http://127.0.0.1:{procs[2].port}", timeout=60,
                            headers={"X-API-Key": key})
        refs = [http.post("/v1/uploads", files={"file": ("p.jpg", data)}).json()["reference"]
                for data, _ in work]
        _store_init(endpoint, *creds)
        s3_client = _STORE.pop()
        runs = {}
        for mode, extra in MODES.items():
            runs[mode] = _run(http, refs, work, per_job, rate, extra)
            runs[mode]["bytes_per_photo"] = sum(
                _stored_bytes(s3_client, job_id) for job_id in runs[mode]["jobs"]) / len(work)
            if mode == next(iter(MODES)):  # the first mode's task figures, before others mix in
                runs[mode]["tasks"] = _task_means(http.get("/metrics").text)
        return {**runs[next(iter(MODES))], "modes": runs, "engine_store_rate": engine_store_rate}
    finally:
        for proc in reversed(procs):
            proc.stop()


def _run(http: httpx.Client, refs: list[str], work: list[tuple[bytes, dict]], per_job: int,
         rate: float, extra: dict) -> dict:
    """Submit every photo (`extra` added to each item) at a steady rate, wait for every job."""
    jobs, submit_ms = [], []
    start = time.perf_counter()
    for n, first in enumerate(range(0, len(work), per_job)):
        time.sleep(max(0.0, start + n / rate - time.perf_counter()))  # steady rate
        items = [{"image": ref, **item, **extra} for ref, (_, item) in
                 zip(refs[first:first + per_job], work[first:first + per_job], strict=True)]
        t = time.perf_counter()
        response = http.post("/v1/jobs", json={"items": items})
        submit_ms.append((time.perf_counter() - t) * 1000)
        jobs.append(response.json()["id"])
    poll_ms, pending = [], set(jobs)
    while pending:
        for job_id in list(pending):
            t = time.perf_counter()
            state = http.get(f"/v1/jobs/{job_id}").json()["state"]
            poll_ms.append((time.perf_counter() - t) * 1000)
            if state in ("succeeded", "failed", "cancelled"):
                pending.discard(job_id)
        time.sleep(1.0)  # a client polls each job about once a second
    elapsed = time.perf_counter() - start
    failed = sum(item["state"] != "succeeded" for job_id in jobs
                 for item in http.get(f"/v1/jobs/{job_id}").json()["items"])
    return {"images_per_s": len(work) / elapsed, "submit_ms": submit_ms, "poll_ms": poll_ms,
            "failed_items": failed, "jobs": jobs}


def _stored_bytes(s3_client, job_id: str) -> int:
    """Bytes of every object under the job's prefix in the service's bucket."""
    total = 0
    for page in s3_client.get_paginator("list_objects_v2").paginate(Bucket=SERVICE_BUCKET,
                                                                   Prefix=f"jobs/{job_id}/"):
        total += sum(obj["Size"] for obj in page.get("Contents", []))
    return total


def _task_means(metrics: str) -> dict[str, tuple[int, float]]:
    """{task: (runs, mean ms)} from the API's Prometheus text."""
    sums, counts = {}, {}
    for line in metrics.splitlines():
        if line.startswith("prism_task_duration_seconds_sum"):
            sums[line.split('"')[1]] = float(line.split()[-1])
        elif line.startswith("prism_task_duration_seconds_count"):
            counts[line.split('"')[1]] = float(line.split()[-1])
    return {t: (int(counts[t]), 1000 * sums[t] / counts[t]) for t in sums if counts.get(t)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--images", type=int, default=200)
    parser.add_argument("--per-job", type=int, default=10)
    parser.add_argument("--rate", type=float, default=20.0, help="job submissions per second")
    parser.add_argument("--distinct", type=int, default=8, help="distinct rendered scenes")
    args = parser.parse_args()
    scenes = _scenes(args.distinct)
    work = [scenes[i % len(scenes)] for i in range(args.images)]
    engine_rate = engine_alone(work)
    with tempfile.TemporaryDirectory() as tmp:
        service = through_service(work, args.per_job, args.rate, Path(tmp))
    table = Table(title=f"{args.images} photos of 1280x1024, {PROCESSES} processes on "
                        f"{PROCESSES} workers")
    for col in ("measure", "value"):
        table.add_column(col)
    table.add_row("engine alone, images/s", f"{engine_rate:.2f}")
    table.add_row("through the service, images/s", f"{service['images_per_s']:.2f}")
    table.add_row("service / engine (target >= 0.7)", f"{service['images_per_s'] / engine_rate:.2f}")
    store_rate = service["engine_store_rate"]
    table.add_row("engine + outputs into the same S3 store, no queue, images/s", f"{store_rate:.2f}")
    table.add_row("  of which storage: (engine + store) / engine", f"{store_rate / engine_rate:.2f}")
    table.add_row("  the queue's own: service / (engine + store)",
                  f"{service['images_per_s'] / store_rate:.2f}")
    for name in ("submit_ms", "poll_ms"):
        values = np.array(service[name])
        table.add_row(f"{name[:-3]} latency p50 / p99 ms ({len(values)} requests)",
                      f"{np.percentile(values, 50):.1f} / {np.percentile(values, 99):.1f}")
    table.add_row("failed items", str(service["failed_items"]))
    for task, (runs, mean_ms) in sorted(service["tasks"].items()):
        table.add_row(f"worker task {task}: runs, mean ms", f"{runs}, {mean_ms:.0f}")
    Console().print(table)
    modes = Table(title="Output modes through the same service, one run each (bytes stored per photo: "
                        f"every object of its jobs; compact ceiling {COMPACT_MAX_BYTES / 1e6:g} MB)")
    for col in ("outputs", "images/s", "MB stored per photo", "failed items"):
        modes.add_column(col)
    for mode, run in service["modes"].items():
        too_big = run["bytes_per_photo"] > COMPACT_MAX_BYTES and "compact" in mode
        over = " (over the ceiling)" if too_big else ""
        modes.add_row(mode, f"{run['images_per_s']:.2f}", f"{run['bytes_per_photo'] / 1e6:.2f}{over}",
                      str(run["failed_items"]))
    Console().print(modes)


if __name__ == "__main__":
    main()

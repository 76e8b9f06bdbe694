"""Throughput model: images per second against worker processes and store bandwidth.

Measures what one image costs each part of the service on the real stack (redis-server,
SeaweedFS, a Celery worker with 2 processes and the API, all on loopback), then predicts, for
1 to 64 worker processes, the rate each part allows and the smallest of them:

* workers: W processes / worker CPU seconds per image (the tasks' CPU, from the processes'
  own CPU time: scan, encode, upload);
* the store: bandwidth / bytes stored per image (every object of the jobs), for a few link
  speeds and two output modes: the service's defaults (csv + ply at PRISM_DEFAULT_SPACING_MM,
  1 mm), as measured; csv + ply at one point per pixel from the bytes ratio of the two in
  benchmarks/service.py;
* Redis: one core (redis-server runs commands on one thread) / Redis CPU seconds per image,
  and its commands per image;
* the API: its processes / API CPU seconds per image (submit and one poll a second).

It assumes each worker process has a core of its own and that the parts do not share cores
(here they do: 2 cores for everything, so every measured cost is loose and the store's and
Redis's CPU are charged to the same cores as the workers'). Costs are per image; a part
"stops scaling" where its limit is the smallest.

    .venv/bin/python benchmarks/throughput_model.py [--images 40] [--per-job 10]
    .venv/bin/python benchmarks/throughput_model.py --costs costs.json   # no measurement
"""

from __future__ import annotations

import argparse
import json
import secrets
import tempfile
import time
from pathlib import Path

import boto3
import cv2
import httpx
import psutil
import redis
from botocore.client import Config

from prism_cli.stack import ManagedProcess, start_api, start_redis, start_s3, start_worker
from prismsynth import Box, render_oblique_view

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
PROCESSES = 2
BUCKET = "prismcloud"
WORKERS = (1, 2, 4, 8, 16, 32, 64)
LINKS_MB_S = {"1 GbE": 117.0, "10 GbE": 1170.0}  # usable payload, MB/s
API_PROCESSES = 4
POLLS_PER_IMAGE = 1.0  # status requests per image (a client polling its 10-image job once a second)
PROCESSES_PER_NODE = 2  # worker processes per worker pod/host (each node's main process polls Redis)
IDLE_S = 10.0
# The service's default outputs (csv + ply at 1 mm spacing) against csv + ply at one point per
# pixel, stored per 1280x1024 clicked photo (benchmarks/service.py --images 100 --kinds clicked,
# the second with PRISM_DEFAULT_SPACING_MM=null: 1.9 MB against 24.8 MB).
PER_PIXEL_BYTES_RATIO = 24.8 / 1.9
MODES = (("default", 1.0), ("per-pixel", PER_PIXEL_BYTES_RATIO))  # bytes against those measured


def _cpu_s(proc: ManagedProcess) -> float:
    """CPU seconds of the process and its children (a worker's pool) so far."""
    assert proc.proc is not None
    root = psutil.Process(proc.proc.pid)
    total = 0.0
    for p in [root, *root.children(recursive=True)]:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.NoSuchProcess:
            pass
    return total


def _photos(count: int) -> list[tuple[bytes, dict]]:
    out = []
    for seed in range(count):
        scene = render_oblique_view(Box(80 + 20 * (seed % 4), 60 + 15 * (seed % 3), 40 + 10 * (seed % 5)),
                                    seed=seed)
        _, jpeg = cv2.imencode(".jpg", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, 90])
        out.append((jpeg.tobytes(), {"points": [list(map(round, scene.points[n])) for n in NAMES],
                                     "focal_px": scene.focal_px,
                                     "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}}))
    return out


def _redis_stats(client: redis.Redis) -> tuple[int, float]:
    calls = sum(v["calls"] for v in client.info("commandstats").values())
    cpu = client.info("cpu")
    return calls, cpu["used_cpu_sys"] + cpu["used_cpu_user"]


def measure(images: int, per_job: int) -> dict[str, float]:
    """Per-image costs on the real stack (one run of `images` 1280x1024 photos)."""
    work = _photos(min(images, 8))
    work = [work[i % len(work)] for i in range(images)]
    key, creds = secrets.token_urlsafe(16), ("bench-key", "bench-secret-" + secrets.token_hex(8))
    with tempfile.TemporaryDirectory() as tmp:
        rs = start_redis(Path(tmp) / "redis")
        s3 = start_s3(Path(tmp) / "s3", *creds)
        env = {"PRISM_API_KEYS": json.dumps({"bench": key}), "PRISM_WEBHOOK_SECRET": "x" * 16,
               "PRISM_REDIS_URL": f"redis://127.0.0.1:{rs.port}/0",
               "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3.port}",
               "PRISM_S3_ACCESS_KEY_ID": creds[0], "PRISM_S3_SECRET_ACCESS_KEY": creds[1]}
        procs = [rs, s3]
        try:
            procs.append(api := start_api(Path(tmp) / "api", env))
            procs.append(worker := start_worker(Path(tmp) / "w", env, PROCESSES))
            http = httpx.Client(base_url=f"http://127.0.0.1:{api.port}", timeout=60,
                                headers={"X-API-Key": key})
            refs = [http.post("/v1/uploads", files={"file": ("p.jpg", data)}).json()["reference"]
                    for data, _ in work]
            client = redis.Redis(port=rs.port)
            while " ready." not in worker.log:
                time.sleep(0.2)
            # Idle: what a worker node costs Redis with nothing to do (its BRPOPs, the watchdog).
            calls0, rcpu0 = _redis_stats(client)
            time.sleep(IDLE_S)
            calls1, rcpu1 = _redis_stats(client)
            idle_calls, idle_cpu = (calls1 - calls0) / IDLE_S, (rcpu1 - rcpu0) / IDLE_S
            wcpu0, acpu0, scpu0 = _cpu_s(worker), _cpu_s(api), _cpu_s(s3)
            start = time.perf_counter()
            jobs = []
            for first in range(0, images, per_job):
                items = [{"image": r, **it} for r, (_, it) in zip(refs[first:first + per_job],
                                                                   work[first:first + per_job], strict=True)]
                jobs.append(http.post("/v1/jobs", json={"items": items}).json()["id"])
            acpu_submit = _cpu_s(api) - acpu0
            pending, polls = set(jobs), 0
            while pending:
                for job_id in list(pending):
                    polls += 1
                    if http.get(f"/v1/jobs/{job_id}").json()["state"] in ("succeeded", "failed", "cancelled"):
                        pending.discard(job_id)
                time.sleep(1.0)
            elapsed = time.perf_counter() - start
            calls2, rcpu2 = _redis_stats(client)
            costs = {"images": images, "elapsed_s": elapsed, "measured_images_per_s": images / elapsed,
                     "worker_cpu_s": (_cpu_s(worker) - wcpu0) / images,
                     "api_submit_cpu_s": acpu_submit / images,
                     "api_poll_cpu_s": (_cpu_s(api) - acpu0 - acpu_submit) / polls,
                     "store_cpu_s": (_cpu_s(s3) - scpu0) / images,
                     "redis_idle_cpu_s_per_s": idle_cpu, "redis_idle_commands_per_s": idle_calls,
                     "redis_cpu_s": max(0.0, rcpu2 - rcpu1 - idle_cpu * elapsed) / images,
                     "redis_commands": max(0.0, calls2 - calls1 - idle_calls * elapsed) / images}
            s3c = boto3.client("s3", endpoint_url=env["PRISM_S3_ENDPOINT_URL"], aws_access_key_id=creds[0],
                               aws_secret_access_key=creds[1], region_name="us-east-1",
                               config=Config(s3={"addressing_style": "path"}))
            stored = 0
            for page in s3c.get_paginator("list_objects_v2").paginate(Bucket=BUCKET, Prefix="jobs/"):
                stored += sum(o["Size"] for o in page.get("Contents", []))
            costs["bytes_stored"] = stored / images
            return costs
        finally:
            for proc in reversed(procs):
                proc.stop()


def _api_cpu_s(costs: dict[str, float]) -> float:
    return costs["api_submit_cpu_s"] + POLLS_PER_IMAGE * costs["api_poll_cpu_s"]


def model(costs: dict[str, float]) -> list[dict[str, object]]:
    """The rate each part allows for each worker count, and the smallest."""
    api_limit = API_PROCESSES / _api_cpu_s(costs)
    rows = []
    for w in WORKERS:
        # One core for redis-server, less what the idle polling of w's nodes takes.
        nodes = -(-w // PROCESSES_PER_NODE)
        redis_limit = max(0.0, 1.0 - nodes * costs["redis_idle_cpu_s_per_s"]) / costs["redis_cpu_s"]
        row: dict[str, object] = {"workers": w, "cpu": w / costs["worker_cpu_s"], "redis": redis_limit}
        for link, mb_s in LINKS_MB_S.items():
            for mode, ratio in MODES:
                store = mb_s * 1e6 / (costs["bytes_stored"] * ratio)
                limits = {"workers": row["cpu"], "store": store, "redis": redis_limit, "api": api_limit}
                bound = min(limits, key=lambda k: float(limits[k]))  # type: ignore[arg-type]
                row[f"{link} {mode}"] = (float(limits[bound]), bound)
        rows.append(row)
    return rows


def print_report(costs: dict[str, float]) -> None:
    print(f"Measured per image (1280x1024 photo, the service's default outputs: csv + ply at 1 mm; "
          f"{costs['images']:.0f} images, "
          f"{PROCESSES} worker processes, {costs['measured_images_per_s']:.2f} images/s end to end here):")
    print(f"  worker CPU {costs['worker_cpu_s'] * 1000:.0f} ms; stored {costs['bytes_stored'] / 1e6:.1f} MB "
          f"(one point per pixel ~{costs['bytes_stored'] * PER_PIXEL_BYTES_RATIO / 1e6:.1f} MB); "
          f"store server CPU {costs['store_cpu_s'] * 1000:.0f} ms")
    print(f"  Redis {costs['redis_commands']:.0f} commands, {costs['redis_cpu_s'] * 1000:.2f} ms CPU "
          f"(one core: {1 / costs['redis_cpu_s']:.0f} images/s), and idle "
          f"{costs['redis_idle_commands_per_s']:.1f} commands/s, "
          f"{costs['redis_idle_cpu_s_per_s'] * 1000:.1f} ms CPU/s per worker node")
    print(f"  API CPU {costs['api_submit_cpu_s'] * 1000:.1f} ms to submit an image (in jobs of 10), "
          f"{costs['api_poll_cpu_s'] * 1000:.1f} ms a status poll ({POLLS_PER_IMAGE:g} per image: "
          f"{API_PROCESSES} processes allow {API_PROCESSES / _api_cpu_s(costs):.0f} images/s)")
    modes = [f"{link} {mode}" for link in LINKS_MB_S for mode, _ in MODES]
    heads = ["workers", "CPU-bound", *modes]
    print("  ".join(f"{h:>18}" if i else f"{h:>7}" for i, h in enumerate(heads)))
    for row in model(costs):
        cells = [f"{row['workers']:>7}", f"{row['cpu']:>18.1f}"]
        for h in heads[2:]:
            rate, bound = row[h]  # type: ignore[misc]
            cells.append(f"{f'{rate:.1f} ({bound})':>18}")
        print("  ".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--images", type=int, default=40)
    parser.add_argument("--per-job", type=int, default=10)
    parser.add_argument("--costs", type=Path, help="per-image costs (JSON, as printed with --json)")
    parser.add_argument("--json", action="store_true", help="print the measured costs as JSON too")
    args = parser.parse_args()
    costs = json.loads(args.costs.read_text()) if args.costs else measure(args.images, args.per_job)
    print_report(costs)
    if args.json:
        print(json.dumps(costs))


if __name__ == "__main__":
    main()

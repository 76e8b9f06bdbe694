"""Service benchmark: a batch through the real stack against the engine alone, side by side.

For each batch kind, one run prints the engine alone, the service, their ratio, the worker's CPU
per photo, the bytes stored per photo, p50/p95 time per item and memory:

* clicked: N one-photo items of 1280x1024 (rendered boxes, `--distinct` scenes repeated), each
  with its own seven points and a scale (pinhole distance), submitted as ONE job;
* station: N photos of parts on one station (`benchmarks/station_batch.py`'s renders, cached
  under --cache), no points, no scale, ONE job.

The engine alone: the same photos (JPEG bytes in memory), the same number of processes, no queue
and no store: decode, measure (`run_scan`, or `scan_on_station`) and write the same files the
service writes for the item (the spec as the service stored it: its default formats and spacing
applied; the preview, overlay and report.json) into memory. Its CPU per photo is the processes'
own (`time.process_time`), its time per item each item's wall time.

The service: redis-server, SeaweedFS, the API and a Celery worker of --processes processes on
loopback (`prism_cli.stack`). Every photo is uploaded first, all sent at once (N uploads in flight,
asyncio; one refused as at capacity, past PRISM_UPLOADS_AT_ONCE, is sent again after its
Retry-After): the API's resident memory (RSS, its process) is sampled meanwhile, its peak printed.
Then one job of N items is submitted and polled (items left out) until final: photos per second
from the submit to the job's end; the worker's CPU (main process and pool, psutil) over that
time per photo; the bytes stored under the job's prefix per photo; each item's time from the
worker's log (`prism.plan_item ... succeeded in`: a batch item is measured whole in that task);
the worker's RSS (all its processes) sampled every 0.5 s: after the first tenth of the batch,
at its end and its peak, and the pool children's peak.

On a machine shared with other work, absolute figures move; the ratios are measured side by
side (the service, then at once the engine alone with the spec the service stored, on the same
cores), so they are what to compare.

    .venv/bin/python benchmarks/service.py [--images 1000] [--kinds clicked,station]
    .venv/bin/python benchmarks/service.py --images 1000 --uploads-only  # the API's memory alone
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import multiprocessing
import re
import secrets
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import boto3
import cv2
import httpx
import numpy as np
import psutil  # type: ignore[import-untyped]
from botocore.client import Config

from prism_cli.client import ApiClient
from prism_cli.stack import ManagedProcess, start_api, start_redis, start_s3, start_worker
from prismsynth import Box, render_oblique_view

sys.path.insert(0, str(Path(__file__).parent))
from station_batch import render as render_station  # the station's photos and station.json

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
BUCKET = "prismcloud"  # the service's default bucket
TARGET = 0.8  # service / engine (issue 38)
CPU_TARGET = 1.5  # worker CPU / engine CPU per photo
TASK_LINE = re.compile(r"Task prism\.plan_item\[[^\]]+\] succeeded in ([0-9.]+)s")


# -- the photos ---------------------------------------------------------------------------------
def clicked_work(count: int, distinct: int) -> list[tuple[bytes, dict[str, Any]]]:
    """(JPEG bytes, the item without its image) per photo: rendered boxes with their points."""
    scenes = []
    for seed in range(distinct):
        box = Box(80 + 20 * (seed % 4), 60 + 15 * (seed % 3), 40 + 10 * (seed % 5))
        scene = render_oblique_view(box, seed=seed)
        _, jpeg = cv2.imencode(".jpg", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR),
                               [cv2.IMWRITE_JPEG_QUALITY, 90])
        scenes.append((jpeg.tobytes(), {"points": [list(map(round, scene.points[n])) for n in NAMES],
                                        "focal_px": scene.focal_px,
                                        "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}}))
    return [scenes[i % len(scenes)] for i in range(count)]


def station_work(count: int, distinct: int, cache: Path) -> tuple[list[tuple[bytes, dict[str, Any]]], Path]:
    photos, _ = render_station(distinct, cache)
    data = [p.read_bytes() for p in photos]
    return [(data[i % len(data)], {}) for i in range(count)], photos[0].parent.parent / "station.json"


# -- the engine alone ---------------------------------------------------------------------------
class _Memory:
    """A `prismcore.outputs.sink.Sink` into memory: counts the bytes."""

    def __init__(self) -> None:
        self.bytes = 0

    def put(self, name: str, data: Any, media_type: str) -> None:
        if isinstance(data, bytes):
            self.bytes += len(data)
            return
        buf = io.BytesIO()
        data(buf)
        self.bytes += buf.tell()


_STATION: list[Any] = []


def _engine_init(station_file: str | None) -> None:
    cv2.setNumThreads(1)  # as the worker's pool processes
    if station_file:
        from prismcore.station import Station

        _STATION.append(Station.model_validate_json(Path(station_file).read_text()))


def _engine_one(args: tuple[bytes, dict[str, Any]]) -> tuple[float, float, int]:
    """What `prism scan` does with the item, into memory: (wall s, CPU s, bytes written)."""
    data, spec_doc = args
    try:
        return _measure_one(data, spec_doc)
    except Exception as exc:  # as text: an exception that does not pickle would hang the pool
        raise RuntimeError(f"engine: {exc!r}") from None


def _measure_one(data: bytes, spec_doc: dict[str, Any]) -> tuple[float, float, int]:
    from prismcore import ScanSpec, run_scan
    from prismcore.io.images import load_image
    from prismcore.outputs.sink import write_outputs
    from prismcore.station.scan import scan_on_station

    wall, cpu = time.perf_counter(), time.process_time()
    photo = load_image(data)
    sink = _Memory()
    if _STATION:
        extra = {k: v for k, v in spec_doc.items() if k in ("formats", "spacing_mm")}
        done = scan_on_station(photo, _STATION[0], "photo", extra)
        if done.result is not None and done.spec is not None:
            write_outputs(done.result, sink, spec=done.spec, images=[photo], preview=True,
                          overlay_max_side=800)
    else:
        spec = ScanSpec.model_validate({**spec_doc, "image": "x"})
        write_outputs(run_scan(spec, photo), sink, spec=spec, images=[photo], preview=True,
                      overlay_max_side=800)
    return time.perf_counter() - wall, time.process_time() - cpu, sink.bytes


def engine_alone(work: list[tuple[bytes, dict[str, Any]]], processes: int,
                 station_file: Path | None) -> dict[str, Any]:
    # spawned, not forked: this process has threads (the samplers, httpx) whose locks a fork copies
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(processes, mp_context=spawn, initializer=_engine_init,
                             initargs=(str(station_file) if station_file else None,)) as pool:
        list(pool.map(_engine_one, work[:processes]))  # warm the processes up
        start = time.perf_counter()
        runs = list(pool.map(_engine_one, work, chunksize=4))
        elapsed = time.perf_counter() - start
    return {"rate": len(work) / elapsed, "item_s": [r[0] for r in runs],
            "cpu_s": sum(r[1] for r in runs) / len(work), "bytes": sum(r[2] for r in runs) / len(work)}


# -- the service --------------------------------------------------------------------------------
def _tree(proc: ManagedProcess) -> list[psutil.Process]:
    assert proc.proc is not None
    root = psutil.Process(proc.proc.pid)
    return [root, *root.children(recursive=True)]


def _cpu_s(proc: ManagedProcess) -> float:
    total = 0.0
    for p in _tree(proc):
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system + t.children_user + t.children_system
    return total


class _Rss(threading.Thread):
    """Samples a process tree's resident memory (MB): the sum over its processes, and the
    largest single process but the root (the worker's pool children)."""

    def __init__(self, proc: ManagedProcess, period_s: float) -> None:
        super().__init__(daemon=True)
        self.proc, self.period_s = proc, period_s
        self.samples: list[tuple[float, float, float]] = []  # (time, total MB, largest child MB)
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.is_set():
            rss = []
            for p in _tree(self.proc):
                try:
                    rss.append(p.memory_info().rss / 2**20)
                except psutil.NoSuchProcess:
                    continue
            self.samples.append((time.perf_counter(), sum(rss), max(rss[1:], default=0.0)))
            self.done.wait(self.period_s)

    def stop(self) -> list[tuple[float, float, float]]:
        self.done.set()
        self.join()
        return self.samples


async def _upload_all(base: str, key: str, work: list[tuple[bytes, dict[str, Any]]]
                      ) -> tuple[list[str], int, int]:
    """Every photo sent at once: len(work) requests in flight. One the API refuses as at
    capacity (503, PRISM_UPLOADS_AT_ONCE) is sent again after its Retry-After, as a client
    should; so is one whose connection failed (most likely a kept-alive connection the server
    closed as it was reused; the same file sent again is the same upload). (The references, how
    many refusals, how many connection errors.)"""
    limits = httpx.Limits(max_connections=len(work), max_keepalive_connections=len(work))
    refused = failed = 0
    async with httpx.AsyncClient(base_url=base, headers={"X-API-Key": key}, timeout=600,
                                 limits=limits) as http:
        async def one(n: int, data: bytes) -> str:
            nonlocal refused, failed
            for _ in range(100):
                try:
                    reply = await http.post("/v1/uploads", files={"file": (f"photo-{n:04d}.jpg", data)})
                except httpx.TransportError:
                    failed += 1
                    await asyncio.sleep(1.0)
                    continue
                if reply.status_code != 503:
                    reply.raise_for_status()
                    return str(reply.json()["reference"])
                refused += 1
                await asyncio.sleep(float(reply.headers.get("Retry-After", "1")))
            raise RuntimeError(f"photo {n}: not taken after 100 tries")
        refs = list(await asyncio.gather(*(one(n, data) for n, (data, _) in enumerate(work))))
    return refs, refused, failed


@dataclass
class _Stack:
    """The service's processes on loopback: redis-server, SeaweedFS, the API and, given a number
    of processes, a worker; the API key and the store's credentials they were started with."""

    procs: list[ManagedProcess]
    key: str
    creds: tuple[str, str]
    env: dict[str, str]


@contextmanager
def _stack(tmp: Path, processes: int | None) -> Iterator[_Stack]:
    key = secrets.token_urlsafe(16)
    creds = ("bench-key", "bench-secret-" + secrets.token_hex(8))
    procs = [start_redis(tmp / "redis"), start_s3(tmp / "s3", *creds)]
    try:
        env = {"PRISM_API_KEYS": json.dumps({"bench": key}), "PRISM_WEBHOOK_SECRET": "x" * 16,
               "PRISM_REDIS_URL": f"redis://127.0.0.1:{procs[0].port}/0",
               "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{procs[1].port}",
               "PRISM_S3_ACCESS_KEY_ID": creds[0], "PRISM_S3_SECRET_ACCESS_KEY": creds[1]}
        procs.append(start_api(tmp / "api", env))
        if processes is not None:
            procs.append(start_worker(tmp / "w", env, processes))
        yield _Stack(procs, key, creds, env)
    finally:
        for proc in reversed(procs):
            proc.stop()


def _uploads(api: ManagedProcess, key: str, work: list[tuple[bytes, dict[str, Any]]]) -> dict[str, Any]:
    """Every photo uploaded at once, the API's RSS sampled meanwhile."""
    api_rss = _Rss(api, 0.1)
    api_rss.start()
    t = time.perf_counter()
    refs, refused, failed = asyncio.run(_upload_all(f"http://127.0.0.1:{api.port}", key, work))
    return {"refs": refs, "refused": refused, "upload_errors": failed, "upload_s": time.perf_counter() - t,
            "api_rss": api_rss.stop()}


def uploads_only(work: list[tuple[bytes, dict[str, Any]]], tmp: Path) -> dict[str, Any]:
    """The upload phase alone (redis-server, SeaweedFS and the API; no worker, no job)."""
    with _stack(tmp, None) as stack:
        return _uploads(stack.procs[2], stack.key, work)


def through_service(work: list[tuple[bytes, dict[str, Any]]], processes: int, tmp: Path,
                    station_file: Path | None) -> dict[str, Any]:
    with _stack(tmp, processes) as stack:
        procs, key, creds, env = stack.procs, stack.key, stack.creds, stack.env
        api, worker = procs[2], procs[3]
        base = f"http://127.0.0.1:{api.port}"
        uploaded = _uploads(api, key, work)
        refs = uploaded["refs"]
        with ApiClient(base, key, timeout=600) as client:
            extra = {"station": client.create_station(station_file, name="bench").id} if station_file else {}
            items = [{"image": ref, **item, **extra} for ref, (_, item) in zip(refs, work, strict=True)]
            worker_rss = _Rss(worker, 0.5)
            worker_rss.start()
            others0 = [_cpu_s(p) for p in procs[:3]]  # redis, the store, the API
            cpu0, start = _cpu_s(worker), time.perf_counter()
            job_id = client.submit({"items": items}).id
            final = client.wait(job_id, timeout=6 * 3600, poll_s=0.5)
            elapsed, cpu = time.perf_counter() - start, _cpu_s(worker) - cpu0
            others = [(_cpu_s(p) - c) / len(work) for p, c in zip(procs[:3], others0, strict=True)]
            rss = worker_rss.stop()
        s3 = boto3.client("s3", endpoint_url=env["PRISM_S3_ENDPOINT_URL"], region_name="us-east-1",
                          aws_access_key_id=creds[0], aws_secret_access_key=creds[1],
                          config=Config(signature_version="s3v4", s3={"addressing_style": "path"}))
        stored = sum(obj["Size"] for page in s3.get_paginator("list_objects_v2").paginate(
            Bucket=BUCKET, Prefix=f"jobs/{job_id}/") for obj in page.get("Contents", []))
        # the item's spec as stored (the service's defaults applied): the job's final document
        job_doc = json.loads(s3.get_object(Bucket=BUCKET, Key=f"jobs/{job_id}/job.json")["Body"].read())
        spec = job_doc["items"][0]["spec"]
        log = (tmp / "w" / "server.log").read_text(errors="replace")
        return {"rate": len(work) / elapsed, "cpu_s": cpu / len(work), "bytes": stored / len(work),
                "item_s": [float(m) for m in TASK_LINE.findall(log)], "failed": final.items_failed,
                "done": final.items_done, "upload_s": uploaded["upload_s"], "api_rss": uploaded["api_rss"],
                "refused": uploaded["refused"], "upload_errors": uploaded["upload_errors"], "worker_rss": rss,
                "spec": spec, "redis_cpu_s": others[0],
                "store_cpu_s": others[1], "api_cpu_s": others[2]}


def _engine_spec(stored: dict[str, Any]) -> dict[str, Any]:
    """What the service's defaults added to the item (its formats and spacing), for the engine."""
    return {k: stored[k] for k in ("formats", "spacing_mm") if stored.get(k) is not None}


# -- the report ---------------------------------------------------------------------------------
def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) * 1000 if values else float("nan")


def report(kind: str, n: int, processes: int, engine: dict[str, Any], service: dict[str, Any]) -> None:
    spec = service["spec"]
    ratio, cpu_ratio = service["rate"] / engine["rate"], service["cpu_s"] / engine["cpu_s"]
    rss = service["worker_rss"]
    t0, t1 = rss[0][0], rss[-1][0]
    early = next(s for s in rss if s[0] >= t0 + 0.1 * (t1 - t0))
    print(f"\n{kind}: {n} photos of 1280x1024, one job, {processes} worker processes; outputs "
          f"{spec.get('formats')} at spacing_mm {spec.get('spacing_mm')} (the service's defaults)")
    print(f"  engine alone          {engine['rate']:7.2f} photos/s   "
          f"CPU {1000 * engine['cpu_s']:5.0f} ms a photo   {engine['bytes'] / 1e6:6.2f} MB written   "
          f"item p50/p95 {_pct(engine['item_s'], 50):.0f} / "
          f"{_pct(engine['item_s'], 95):.0f} ms")
    print(f"  through the service   {service['rate']:7.2f} photos/s   "
          f"CPU {1000 * service['cpu_s']:5.0f} ms a photo   {service['bytes'] / 1e6:6.2f} MB stored    "
          f"item p50/p95 {_pct(service['item_s'], 50):.0f} / "
          f"{_pct(service['item_s'], 95):.0f} ms ({len(service['item_s'])} tasks)")
    print(f"  service / engine      {ratio:7.2f}   (target >= {TARGET})")
    print(f"  worker CPU / engine   {cpu_ratio:7.2f}   (target <= {CPU_TARGET}; worker, all processes)")
    print("  besides the worker    CPU ms a photo: the store's server "
          f"{1000 * service['store_cpu_s']:.0f}, Redis {1000 * service['redis_cpu_s']:.0f}, "
          f"the API {1000 * service['api_cpu_s']:.0f} (same cores)")
    print(f"  items done / failed   {service['done']} / {service['failed']}")
    print(f"  worker RSS MB         after a tenth {early[1]:.0f}, at the end {rss[-1][1]:.0f}, peak "
          f"{max(s[1] for s in rss):.0f} (all processes); largest pool process peak "
          f"{max(s[2] for s in rss):.0f}, after a tenth {early[2]:.0f}, at the end {rss[-1][2]:.0f}")
    print_uploads(n, service)


def print_uploads(n: int, uploaded: dict[str, Any]) -> None:
    api = uploaded["api_rss"]
    print(f"  API RSS MB            {api[0][1]:.0f} before, peak {max(s[1] for s in api):.0f} "
          f"with {n} uploads sent at once ({uploaded['upload_s']:.0f} s for all; "
          f"{uploaded['refused']} refused as at capacity and {uploaded['upload_errors']} connection errors, "
          f"each sent again), {api[-1][1]:.0f} after")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=1000)
    parser.add_argument("--kinds", default="clicked,station")
    parser.add_argument("--distinct", type=int, default=8, help="distinct photos of each kind")
    parser.add_argument("--processes", type=int, default=2, help="engine processes and worker pool")
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "prism-station-batch")
    parser.add_argument("--uploads-only", action="store_true",
                        help="only send the clicked photos at once to the API (no worker, no job, "
                        "no engine): its memory with every upload in flight")
    args = parser.parse_args()
    if args.uploads_only:
        with tempfile.TemporaryDirectory() as tmp:
            uploaded = uploads_only(clicked_work(args.images, args.distinct), Path(tmp))
        print(f"uploads: {args.images} photos of 1280x1024 sent at once to one API process")
        print_uploads(args.images, uploaded)
        return
    kinds = args.kinds.split(",")
    if unknown := set(kinds) - {"clicked", "station"}:
        raise SystemExit(f"unknown kinds {sorted(unknown)}: clicked, station")
    # Every photo first: a fork after the samplers' threads ran could deadlock the render pool.
    works = {"clicked": (clicked_work(args.images, args.distinct), None) if "clicked" in kinds else None,
             "station": station_work(args.images, args.distinct, args.cache) if "station" in kinds else None}
    for kind in kinds:
        work, station_file = works[kind]  # type: ignore[misc]
        with tempfile.TemporaryDirectory() as tmp:
            service = through_service(work, args.processes, Path(tmp), station_file)
        spec = _engine_spec(service["spec"])
        engine = engine_alone([(data, {**item, **spec}) for data, item in work], args.processes, station_file)
        report(kind, args.images, args.processes, engine, service)

if __name__ == "__main__":
    main()

"""Worker cost: the worker's CPU per image against the engine's own, side by side in one run.

1. The engine alone, in this process, on the same photos (decoded beforehand): plan, scan and
   finish (`prismcore.run_scan`), no decoding, writing or storing; its wall and CPU time per
   photo (the median of `--runs` runs of each photo, averaged over the photos).
2. The same photos through the real stack (redis-server, SeaweedFS, the API and a Celery worker
   with 2 processes, all on loopback), submitted as jobs of `--per-job` items with the
   service's default outputs (or the `--formats` given): the worker's CPU seconds (its main
   process and its pool, from psutil) from the first submit to the last job's end, per photo.

It prints both, and the ratio of worker CPU per photo to the engine's CPU per photo (target:
at most 2). With `--profile`, py-spy (`pip install py-spy`; not in the locks) samples the
worker's processes meanwhile, and the samples are summed per kind of work (a sample's stack
counts for the first kind in KINDS it contains); each kind's share of the busy samples is
printed, and that share of the measured worker CPU as ms per photo.

    .venv/bin/python benchmarks/worker_cost.py [--images 40] [--per-job 10] [--formats csv,ply]
    .venv/bin/python benchmarks/worker_cost.py --profile /tmp/worker.txt   # where the CPU goes
"""

from __future__ import annotations

import argparse
import json
import secrets
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import httpx
import psutil

from prism_cli.stack import ManagedProcess, start_api, start_redis, start_s3, start_worker
from prismcore import ScanSpec, run_scan
from prismcore.io.images import load_image

sys.path.insert(0, str(Path(__file__).parent))
from throughput_model import _photos  # the same photos: 1280x1024, with a scale

PROCESSES = 2
TARGET_RATIO = 2.0
SAMPLE_HZ = 100
# Kinds of work, by a marker in a sampled stack's frames; a stack counts for the first it has.
# py-spy's own idle detection does not tell a thread blocked in epoll or on a lock from a
# running one here, so a stack whose innermost frame is one of WAITS counts as waiting.
WAITING = "(waiting: epoll, locks, sockets; not CPU)"
WAITS = ("_epoll.poll (", "Condition.wait (", "Event.wait (", "Connection._recv (", "SocketIO.readinto (",
         "do_poll (", "select (", "sleep (")
KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("object store (boto3, HTTP)", ("botocore/", "boto3/", "s3transfer/", "urllib3/", "(http/client.py")),
    ("Redis (job store)", ("redis/", "prism_common/store.py")),
    ("CSV writer", ("write_csv (",)),
    ("preview.ply (decimate, PLY)", ("decimate (", "_put_preview.<locals>.<lambda> (")),
    ("PLY writer", ("write_ply (",)),
    ("LAS/LAZ writer", ("write_las (",)),
    ("glb model", ("box_glb (",)),
    ("overlay (JPEG)", ("overlay_from_report (", "encode_overlay (", "encode_png (", "display_size (")),
    ("report.json (JSON)", ("json/",)),
    ("photo decode", ("load_image (",)),
    ("engine (scan)", ("scan_found (", "run_scan (", "plan_scan (", "finish_scan (", "resolve_points (")),
    ("Celery, kombu, billiard", ("celery/", "kombu/", "billiard/", "vine/")),
)


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


def engine_cost(work: list[tuple[bytes, dict]], runs: int) -> tuple[float, float]:
    """(wall ms, CPU ms) of plan + scan + finish per photo, in this process."""
    walls, cpus = [], []
    for data, item in work:
        spec = ScanSpec.model_validate({"image": "x", **item})
        image = load_image(data)
        run_scan(spec, image)  # warm-up
        w, c = [], []
        for _ in range(runs):
            c0, w0 = time.process_time(), time.perf_counter()
            run_scan(spec, image)
            w.append(time.perf_counter() - w0)
            c.append(time.process_time() - c0)
        walls.append(statistics.median(w))
        cpus.append(statistics.median(c))
    return statistics.fmean(walls) * 1000, statistics.fmean(cpus) * 1000


def _start_profiler(worker: ManagedProcess, out: Path) -> subprocess.Popen[bytes]:
    spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    assert worker.proc is not None
    return subprocess.Popen([spy, "record", "--pid", str(worker.proc.pid), "--subprocesses",
                             "--format", "raw", "--nolineno", "--rate", str(SAMPLE_HZ), "-o", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def profile_by_kind(raw: Path) -> list[tuple[str, float]]:
    """The share of py-spy's samples (raw, collapsed output) that each kind of work has."""
    counts: Counter[str] = Counter()
    for line in raw.read_text().splitlines():
        stack, _, n = line.rpartition(" ")
        if not stack:
            continue
        if any(w in stack.rpartition(";")[2] for w in WAITS):
            counts[WAITING] += int(n)
            continue
        kind = next((k for k, marks in KINDS if any(m in stack for m in marks)), "other")
        counts[kind] += int(n)
    total = sum(counts.values()) or 1
    return [(k, n / total) for k, n in counts.most_common()]


def worker_cost(work: list[tuple[bytes, dict]], per_job: int, formats: list[str] | None,
                profile: Path | None) -> float:
    """Worker CPU ms per photo for these photos as jobs through the real stack."""
    key, creds = secrets.token_urlsafe(16), ("bench-key", "bench-secret-" + secrets.token_hex(8))
    with tempfile.TemporaryDirectory() as tmp:
        rs = start_redis(Path(tmp) / "redis")
        s3 = start_s3(Path(tmp) / "s3", *creds)
        env = {"PRISM_API_KEYS": json.dumps({"bench": key}), "PRISM_WEBHOOK_SECRET": "x" * 16,
               "PRISM_REDIS_URL": f"redis://127.0.0.1:{rs.port}/0",
               "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3.port}",
               "PRISM_S3_ACCESS_KEY_ID": creds[0], "PRISM_S3_SECRET_ACCESS_KEY": creds[1]}
        procs = [rs, s3]
        spy = None
        try:
            procs.append(api := start_api(Path(tmp) / "api", env))
            procs.append(worker := start_worker(Path(tmp) / "w", env, PROCESSES))
            http = httpx.Client(base_url=f"http://127.0.0.1:{api.port}", timeout=60,
                                headers={"X-API-Key": key})
            refs = [http.post("/v1/uploads", files={"file": ("p.jpg", data)}).json()["reference"]
                    for data, _ in work]
            while " ready." not in worker.log:
                time.sleep(0.2)
            extra = {} if formats is None else {"formats": formats}
            if profile is not None:
                spy = _start_profiler(worker, profile)
                time.sleep(1.0)  # py-spy attaches
            cpu0 = _cpu_s(worker)
            jobs = []
            for first in range(0, len(work), per_job):
                chunk = zip(refs[first:first + per_job], work[first:first + per_job], strict=True)
                items = [{"image": r, **it, **extra} for r, (_, it) in chunk]
                answer = http.post("/v1/jobs", json={"items": items})
                answer.raise_for_status()
                jobs.append(answer.json()["id"])
            pending = set(jobs)
            while pending:
                for job_id in list(pending):
                    job = http.get(f"/v1/jobs/{job_id}").json()
                    if job["state"] in ("succeeded", "failed", "cancelled"):
                        if job["state"] != "succeeded":
                            raise RuntimeError(f"job {job_id} {job['state']}: {json.dumps(job)[:2000]}")
                        pending.discard(job_id)
                time.sleep(0.5)
            cpu = _cpu_s(worker) - cpu0
            return cpu * 1000 / len(work)
        finally:
            if spy is not None:
                spy.send_signal(signal.SIGINT)  # py-spy writes its file on SIGINT
                spy.wait(60)
            for proc in reversed(procs):
                proc.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--images", type=int, default=40)
    parser.add_argument("--per-job", type=int, default=10)
    parser.add_argument("--runs", type=int, default=5, help="engine runs per distinct photo")
    parser.add_argument("--formats", help="comma-separated formats for every item (default: the service's)")
    parser.add_argument("--profile", type=Path, help="py-spy's raw samples of the worker, to this file")
    args = parser.parse_args()
    distinct = _photos(min(args.images, 8))
    work = [distinct[i % len(distinct)] for i in range(args.images)]
    formats = args.formats.split(",") if args.formats else None
    engine_wall, engine_cpu = engine_cost(distinct, args.runs)
    worker = worker_cost(work, args.per_job, formats, args.profile)
    print(f"{args.images} photos of 1280x1024 (scale given), jobs of {args.per_job}, "
          f"outputs {'the service default' if formats is None else '+'.join(formats)}, "
          f"{PROCESSES} worker processes")
    print(f"  engine (plan + scan + finish, in process): {engine_wall:.1f} ms wall, "
          f"{engine_cpu:.1f} ms CPU per photo")
    print(f"  worker CPU (main process + pool, psutil): {worker:.1f} ms per photo")
    print(f"  worker CPU beyond the engine's: {worker - engine_cpu:.1f} ms per photo")
    ratio = worker / engine_cpu
    print(f"  ratio worker CPU / engine CPU: {ratio:.2f} (target <= {TARGET_RATIO:g}: "
          f"{'met' if ratio <= TARGET_RATIO else 'NOT met'}); / engine wall: {worker / engine_wall:.2f}")
    if args.profile is not None and args.profile.exists():
        shares = profile_by_kind(args.profile)
        busy = 1.0 - dict(shares).get(WAITING, 0.0)
        # py-spy samples threads that are running or runnable: on a loaded machine that is
        # more than their CPU time, so each kind's share of the busy samples is scaled to the
        # worker CPU psutil measured.
        print(f"  where the worker's CPU goes (py-spy, {SAMPLE_HZ} samples/s; each kind's share of "
              f"the busy samples times the worker CPU, ms per photo):")
        for kind, share in shares:
            cost = "" if kind == WAITING else f"{worker * share / busy:8.1f}"
            print(f"    {kind:<42} {share:6.1%} {cost}")


if __name__ == "__main__":
    main()

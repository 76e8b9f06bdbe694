"""Station batch benchmark: N photos of parts on ONE station through the real service, nothing
else given, the way a factory submits them.

Renders N photos of 1280x1024 of one station setup (`prismsynth.station`, one part each, its truth
the rendered box), cached on disk under --cache so reruns render nothing. Starts the stack as
`benchmarks/service.py` does (`prism_cli.stack`: redis-server, SeaweedFS, the API under uvicorn,
one Celery worker of 2 processes), stores the station with `prism station upload station.json`,
submits every photo in ONE job with `prism submit --station ID photos/*.jpg` (a subprocess, as a
factory's script would run it: 500 paths on one command line; the CLI uploads each photo, then
posts one job of N items), polls the job's state without its items (`item_limit=0`, as
`prism wait` does) until final, then reads the items a page at a time and the whole job once.

Prints: items submitted, done, found, refused by reason, lost (submitted but never final: must be
0); accuracy against the renders' truth (dimensions within max(1 %, 1 mm), within 3 sigma, > 5 %
off without a warning); wall time of the upload + submit and of the whole run, photos per second;
the worker's CPU per photo (all its processes, from psutil) beside the engine's own (the worker's
call, `scan_on_station` on the decoded photo, in this process with OpenCV on one thread, on a
sample of the photos), and the API's CPU per photo.

    nice .venv/bin/python benchmarks/station_batch.py [--photos 500] [--engine-sample 20]
        [--cache /tmp/prism-station-batch] [--distinct N] [--client]

--client submits with the Python client (`ApiClient.upload` each photo, one `submit`) instead of
the CLI.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import re
import secrets
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import psutil  # type: ignore[import-untyped]

from prism_cli.client import ApiClient
from prism_cli.stack import ManagedProcess, start_api, start_redis, start_s3, start_worker

SIZE = (1280, 1024)
SETUP_SEED = 3
PART_SEED0 = 10_000
PROCESSES = 2
PAGE = 100  # items read per GET when the job is done
PRISM = str(Path(sys.executable).with_name("prism"))


def _render_one(args: tuple[int, str]) -> dict[str, Any]:
    """Render part `seed` on the station and write its JPEG (q 95); its truth."""
    from prismsynth.station import station_scene, station_setup

    seed, target = args
    cv2.setNumThreads(1)
    scene = station_scene(seed, station_setup(SETUP_SEED, image_size=SIZE))
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(scene.photo, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok and scene.box is not None
    Path(target).write_bytes(data.tobytes())
    return {"seed": seed, "photo": Path(target).name, "truth": scene.box.dimensions}


def _station_json(folder: Path) -> Path:
    """station.json calibrated with the true camera from the station's plate (as the tests do)."""
    from prismcore.camera import CameraModel
    from prismcore.station import calibrate_station
    from prismsynth.station import station_scene, station_setup

    target = folder / "station.json"
    if target.exists():
        return target
    setup = station_setup(SETUP_SEED, image_size=SIZE)
    plate = station_scene(100, setup).plate
    w, h = setup.image_size
    camera = CameraModel(fx=setup.K[0, 0], fy=setup.K[1, 1], cx=setup.K[0, 2], cy=setup.K[1, 2],
                         dist=[float(v) for v in setup.dist], image_width=w, image_height=h)
    station = calibrate_station(setup.board, plate, camera=camera, plate=plate)
    target.write_text(station.model_dump_json())
    return target


def render(count: int, cache: Path) -> tuple[list[Path], list[dict[str, float]]]:
    """The first `count` photos of the station (rendered once, then read from `cache`)."""
    folder = cache / f"setup{SETUP_SEED}-{SIZE[0]}x{SIZE[1]}"
    (folder / "photos").mkdir(parents=True, exist_ok=True)
    truth_file = folder / "truth.jsonl"
    known = {}
    if truth_file.exists():
        for line in truth_file.read_text().splitlines():
            row = json.loads(line)
            known[row["seed"]] = row
    seeds = [PART_SEED0 + i for i in range(count)]
    todo = [(s, str(folder / "photos" / f"part-{s - PART_SEED0:04d}.jpg")) for s in seeds
            if s not in known or not (folder / "photos" / known[s]["photo"]).exists()]
    if todo:
        print(f"rendering {len(todo)} photos into {folder} ...", flush=True)
        started = time.perf_counter()
        # spawned, not forked: a caller that ran OpenCV or numpy first holds their threads' locks,
        # which a fork copies locked (benchmarks/service.py's render pool hung on them)
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(PROCESSES, mp_context=spawn) as pool, truth_file.open("a") as out:
            for row in pool.map(_render_one, todo, chunksize=4):
                known[row["seed"]] = row
                out.write(json.dumps(row) + "\n")
                out.flush()
        print(f"  rendered in {time.perf_counter() - started:.0f} s", flush=True)
    _station_json(folder)
    return ([folder / "photos" / known[s]["photo"] for s in seeds], [known[s]["truth"] for s in seeds])


Truth = list[dict[str, float]]


def reuse(photos: list[Path], truth: Truth, count: int) -> tuple[list[Path], Truth]:
    """`count` photos from fewer renders: photo i >= len(photos) is render i % len(photos) encoded
    again at another JPEG quality (its own bytes, so its own upload; the same truth)."""
    out, out_truth = list(photos), list(truth)
    for i in range(len(photos), count):
        source, copy = photos[i % len(photos)], i // len(photos)
        target = source.with_name(f"{source.stem}-copy{copy}.jpg")
        if not target.exists():
            image = cv2.imread(str(source))
            assert image is not None, source
            ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95 - copy])
            assert ok
            target.write_bytes(data.tobytes())
        out.append(target)
        out_truth.append(truth[i % len(photos)])
    return out, out_truth


def _cpu_s(proc: ManagedProcess) -> float:
    """CPU seconds (user + system) of a process we started and all its descendants, the ended
    ones it has waited for included."""
    assert proc.proc is not None
    root = psutil.Process(proc.proc.pid)
    total = 0.0
    for p in [root, *root.children(recursive=True)]:
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system + (t.children_user + t.children_system if p is root else 0.0)
    return total


def engine_cpu_ms(photos: list[Path], station_file: Path, sample: int) -> list[float]:
    """CPU ms per photo of the worker's own call on decoded photos, one thread, no service."""
    from prismcore import InputError
    from prismcore.io.images import load_image
    from prismcore.station import Station
    from prismcore.station.scan import scan_on_station

    cv2.setNumThreads(1)
    station = Station.model_validate_json(station_file.read_text())
    spent = []
    for path in photos[:sample]:
        image = load_image(path.read_bytes())
        started = time.process_time()
        try:
            scan_on_station(image, station, path.name, {})
        except InputError:
            continue
        spent.append((time.process_time() - started) * 1000)
    return spent


def _submit(photos: list[Path], station_file: Path, base: str, key: str, use_client: bool) -> tuple[str, str]:
    """Store the station and submit every photo on it as one job; (station id, job id)."""
    if use_client:
        with ApiClient(base, key, timeout=120) as client:
            station_id = client.create_station(station_file, name="batch").id
            items = [{"image": client.upload(p), "station": station_id} for p in photos]
            return station_id, client.submit({"items": items}).id
    env = {**os.environ, "PRISM_API_URL": base, "PRISM_API_KEY": key}
    run = subprocess.run([PRISM, "station", "upload", str(station_file), "--name", "batch"], env=env,
                         capture_output=True, text=True, check=False)
    if run.returncode != 0:
        raise SystemExit(f"prism station upload failed: {run.stdout}{run.stderr}")
    station_id = run.stdout.strip()
    run = subprocess.run([PRISM, "submit", "--station", station_id, *map(str, photos)], env=env,
                         capture_output=True, text=True, check=False)
    if run.returncode != 0:
        raise SystemExit(f"prism submit failed ({run.returncode}): {run.stdout}{run.stderr}")
    return station_id, run.stdout.strip().splitlines()[-1]


def through_service(photos: list[Path], station_file: Path, use_client: bool, tmp: Path) -> dict[str, Any]:
    key = secrets.token_urlsafe(16)
    creds = ("bench-key", "bench-secret-" + secrets.token_hex(8))
    redis = start_redis(tmp / "redis")
    s3 = start_s3(tmp / "s3", *creds)
    env = {"PRISM_API_KEYS": json.dumps({"bench": key}), "PRISM_WEBHOOK_SECRET": "x" * 16,
           "PRISM_REDIS_URL": f"redis://127.0.0.1:{redis.port}/0",
           "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3.port}",
           "PRISM_S3_ACCESS_KEY_ID": creds[0], "PRISM_S3_SECRET_ACCESS_KEY": creds[1]}
    procs = [redis, s3]
    try:
        procs.append(start_api(tmp / "api", env))
        procs.append(start_worker(tmp / "w", env, PROCESSES))
        api, worker = procs[2], procs[3]
        base = f"http://127.0.0.1:{api.port}"
        worker_cpu0, api_cpu0 = _cpu_s(worker), _cpu_s(api)
        started = time.perf_counter()
        station_id, job_id = _submit(photos, station_file, base, key, use_client)
        submitted_s = time.perf_counter() - started
        print(f"submitted job {job_id}: {len(photos)} photos on station {station_id} in {submitted_s:.0f} s",
              flush=True)
        with ApiClient(base, key, timeout=120) as client:
            polls = 0

            def seen(job: Any) -> None:
                nonlocal polls
                polls += 1
                if polls % 60 == 0:
                    print(f"  {job.state.value} {job.items_done}/{job.item_count}", flush=True)

            final = client.wait(job_id, timeout=6 * 3600, poll_s=1.0, on_update=seen)
            elapsed = time.perf_counter() - started
            worker_cpu, api_cpu = _cpu_s(worker) - worker_cpu0, _cpu_s(api) - api_cpu0
            items: list[dict[str, Any]] = []
            page_ms = []
            for offset in range(0, final.item_count, PAGE):
                t = time.perf_counter()
                page = client._call("GET", f"/v1/jobs/{job_id}",
                                    params={"item_offset": offset, "item_limit": PAGE}).json()
                page_ms.append((time.perf_counter() - t) * 1000)
                items.extend(page["items"])
            t = time.perf_counter()
            whole = client._call("GET", f"/v1/jobs/{job_id}").json()
            whole_ms = (time.perf_counter() - t) * 1000
            t = time.perf_counter()
            table = client.results(job_id)
            table_ms = (time.perf_counter() - t) * 1000
        return {"job": final.model_dump(mode="json"), "items": items, "whole_items": len(whole["items"]),
                "submit_s": submitted_s, "elapsed_s": elapsed, "worker_cpu_s": worker_cpu,
                "api_cpu_s": api_cpu, "page_ms": page_ms, "whole_ms": whole_ms, "polls": polls,
                "table_rows": len(table.rows), "table_ms": table_ms}
    finally:
        for proc in reversed(procs):
            proc.stop()


def _spread(values: list[float]) -> str:
    return f"{statistics.median(values):.0f} / {np.percentile(values, 90):.0f} / {max(values):.0f}"


def report(n: int, truth: list[dict[str, float]], run: dict[str, Any], engine_ms: list[float]) -> None:
    items = run["items"]
    states = Counter(item["state"] for item in items)
    final = {"succeeded", "failed", "cancelled"}
    lost = n - sum(item["state"] in final for item in items)
    reasons: Counter[str] = Counter()
    examples: dict[str, str] = {}
    within = in3 = total = silent = 0
    worst: list[tuple[float, str]] = []
    for item in items:
        if item["state"] == "failed":
            text = str(item.get("error") or "(no reason given)")
            head, _, rest = text.partition(": ")
            reason = rest if rest and " " not in head else text  # without the photo's name
            shape = re.sub(r"\d+(\.\d+)?", "#", reason)  # one line per kind of refusal
            reasons[shape] += 1
            examples.setdefault(shape, reason)
            continue
        if item["state"] != "succeeded":
            continue
        result, true = item["result"], truth[item["index"]]
        dims, sigma, warned = result["dimensions"], result["uncertainty"] or {}, bool(result["warnings"])
        for key, value in true.items():
            err = float(dims[key]) - value
            total += 1
            within += abs(err) <= max(0.01 * value, 1.0)
            in3 += key in sigma and abs(err) <= 3 * sigma[key]
            silent += abs(err) > 0.05 * value and not warned
            worst.append((abs(err) / value, f"item {item['index']} {key} {value:.1f} -> {dims[key]:.1f} "
                                             f"+- {sigma.get(key, float('nan')):.2f} mm"
                                             f"{' (warned)' if warned else ''}"))
    found = states["succeeded"]
    print(f"\n{n} photos of {SIZE[0]}x{SIZE[1]} ({len(set(map(json.dumps, truth)))} parts) on one "
          f"station, one job, worker of {PROCESSES} processes")
    print(f"items submitted                {n}")
    print(f"items listed                   {len(items)} (pages of {PAGE}); whole job GET: "
          f"{run['whole_items']} items; results table rows: {run['table_rows']}")
    print(f"job state                      {run['job']['state']}, items done {run['job']['items_done']}")
    print(f"done (final)                   {sum(states[s] for s in final)}   {dict(states)}")
    print(f"found (measured)               {found} ({found / n:.1%})")
    for shape, count in reasons.most_common():
        print(f"  refused x{count}: {examples[shape]}")
    print(f"lost                           {lost}   must be 0")
    print(f"within max(1 %, 1 mm)          {within / max(total, 1):7.1%}   ({total} dimensions)")
    print(f"within 3 sigma                 {in3 / max(total, 1):7.1%}")
    print(f"> 5 % off without a warning    {silent:7d}")
    for rel, text in sorted(worst, reverse=True)[:3]:
        print(f"  worst {rel:6.1%}: {text}")
    print(f"upload + submit wall           {run['submit_s']:7.0f} s")
    print(f"whole run wall                 {run['elapsed_s']:7.0f} s   {n / run['elapsed_s']:.2f} photos/s")
    print(f"worker CPU a photo             {1000 * run['worker_cpu_s'] / n:7.0f} ms  (all its processes)")
    print(f"API CPU a photo                {1000 * run['api_cpu_s'] / n:7.0f} ms")
    if engine_ms:
        print(f"engine alone, CPU ms a photo   {statistics.median(engine_ms):7.0f} median "
              f"(median / p90 / worst {_spread(engine_ms)}, {len(engine_ms)} photos, one thread)")
    print(f"state polls                    {run['polls']} (items left out)")
    print(f"page GET ms (100 items)        {_spread(run['page_ms'])}  median / p90 / worst")
    print(f"whole job GET ms               {run['whole_ms']:7.0f}   results table {run['table_ms']:.0f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photos", type=int, default=500)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "prism-station-batch")
    parser.add_argument("--distinct", type=int, default=0, help="render only this many parts and "
                        "make up --photos from them, each again at another JPEG quality (0: all distinct)")
    parser.add_argument("--engine-sample", type=int, default=20, help="photos timed in the engine alone")
    parser.add_argument("--client", action="store_true", help="submit with the Python client, not the CLI")
    parser.add_argument("--dump", type=Path, help="write the items (JSON, with their truth) here")
    args = parser.parse_args()
    distinct = min(args.distinct or args.photos, args.photos)
    photos, truth = reuse(*render(distinct, args.cache), args.photos)
    station_file = photos[0].parent.parent / "station.json"
    engine_ms = engine_cpu_ms(photos, station_file, args.engine_sample)
    with tempfile.TemporaryDirectory() as tmp:
        run = through_service(photos, station_file, args.client, Path(tmp))
    if args.dump:
        args.dump.write_text(json.dumps([{**item, "photo": str(photos[item["index"]]),
                                          "truth": truth[item["index"]]} for item in run["items"]]))
    report(len(photos), truth, run, engine_ms)


if __name__ == "__main__":
    main()

"""Video benchmark: frames per second of a 1280x1024 video through the engine.

Each row runs the whole local path on the same clip: probe, select, decode (streamed), scan
(plan, tiles, cloud) and write CSV + PLY into memory. Rows side by side:
  * decode only (the floor the codec sets),
  * the engine on every frame, per codec (MJPEG AVI, H.264 MP4 when imageio-ffmpeg is there),
  * the engine on the K sharpest frames (the rating pass decodes every candidate).
  * the same MJPEG clip through the service: uploaded, submitted as one video item (every
    frame), split by a worker and measured by frame tasks on 2 worker processes, each frame's
    CSV, PLY, preview and report stored in SeaweedFS (all on this machine's 2 cores); timed from
    submit to the job's end.

Run: .venv/bin/python benchmarks/video.py [--frames N] [--poses N]
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import json
import secrets
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import cycle, islice
from pathlib import Path

import httpx
import numpy as np
from rich.console import Console
from rich.table import Table

from prism_cli.stack import start_api, start_redis, start_s3, start_worker
from prismcore import ScanSpec, run_scan
from prismcore.outputs.writers import write_format
from prismcore.spec import FrameSelection
from prismcore.video.frames import frame_spec, iter_frames, probe_video, select_frames
from prismsynth import Box, render_clip, write_video

SIZE = (1280, 1024)
FINAL = ("succeeded", "failed", "cancelled")
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


@dataclass
class Row:
    what: str
    clip: str
    frames: int
    seconds: float
    stages_ms: dict[str, float] = field(default_factory=dict)  # per frame
    note: str = ""

    @property
    def fps(self) -> float:
        return self.frames / self.seconds


def make_clip(folder: Path, codec: str, frames: int, poses: int) -> tuple[Path, ScanSpec]:
    """A 1280x1024 clip of `frames` frames (`poses` distinct renders, cycled) and a spec for it."""
    scenes = render_clip(Box(120.0, 80.0, 60.0), poses, image_size=SIZE, seed=1)
    path = folder / ("clip.mp4" if codec == "h264" else f"clip_{codec}.avi")
    write_video(islice(cycle(s.image for s in scenes), frames), path, codec=codec)
    spec = ScanSpec.model_validate({
        "image": str(path), "points": [list(np.rint(scenes[0].points[n])) for n in NAMES],
        "focal_px": scenes[0].focal_px, "frames": {},
        "scale": {"kind": "pinhole", "distance_mm": scenes[0].distance_mm}})
    return path, spec


def decode_only(path: Path) -> Row:
    start = time.perf_counter()
    info = probe_video(path)
    n = sum(1 for _ in iter_frames(path, range(info.frame_count)))
    return Row("decode only (RGB frames)", path.name, n, time.perf_counter() - start)


def engine(path: Path, spec: ScanSpec, selection: FrameSelection, what: str) -> Row:
    """probe + select + decode + scan + CSV and PLY written to memory, for every selected frame."""
    start = time.perf_counter()
    info = probe_video(path)
    indices = select_frames(path, selection, info, max_frames=info.frame_count)
    stages = {"select": time.perf_counter() - start, "decode": 0.0, "scan": 0.0, "write": 0.0}
    written = 0
    tick = time.perf_counter()
    for index, frame in iter_frames(path, indices):
        stages["decode"] += time.perf_counter() - tick
        one = frame_spec(spec, index)
        tick = time.perf_counter()
        result = run_scan(one, frame)
        stages["scan"] += time.perf_counter() - tick
        tick = time.perf_counter()
        for kind in one.formats:
            buf = io.BytesIO()
            write_format(kind, buf, result.cloud, one)
            written += buf.tell()
        stages["write"] += time.perf_counter() - tick
        tick = time.perf_counter()
    seconds = time.perf_counter() - start
    return Row(what, path.name, len(indices), seconds,
               {k: v * 1000 / len(indices) for k, v in stages.items()},
               f"{written / len(indices) / 2**20:.1f} MiB CSV+PLY per frame")


def through_service(path: Path, spec: ScanSpec) -> Row:
    """The clip as one video item through the real stack (2 worker processes)."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        creds = ("bench-key", "bench-secret-" + secrets.token_hex(8))
        key = secrets.token_urlsafe(16)
        redis = start_redis(work / "redis")
        s3 = start_s3(work / "s3", *creds)
        env = {"PRISM_API_KEYS": json.dumps({"bench": key}), "PRISM_WEBHOOK_SECRET": "x" * 16,
               "PRISM_REDIS_URL": f"redis://127.0.0.1:{redis.port}/0",
               "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3.port}",
               "PRISM_S3_ACCESS_KEY_ID": creds[0], "PRISM_S3_SECRET_ACCESS_KEY": creds[1]}
        procs = [redis, s3, start_api(work / "api", env), start_worker(work / "w", env, 2)]
        try:
            http = httpx.Client(base_url=f"http://127.0.0.1:{procs[2].port}", timeout=60,
                                headers={"X-API-Key": key})
            ref = http.post("/v1/uploads", files={"file": (path.name, path.read_bytes())}).json()
            item = {**spec.model_dump(mode="json", exclude_none=True), "image": ref["reference"]}
            start = time.perf_counter()
            job_id = http.post("/v1/jobs", json={"items": [item]}).json()["id"]
            while (job := http.get(f"/v1/jobs/{job_id}").json())["state"] not in FINAL:
                time.sleep(0.2)
            seconds = time.perf_counter() - start
        finally:
            for proc in reversed(procs):
                proc.stop()
    measured = sum(f["state"] == "succeeded" for f in job["items"][0]["frames"])
    return Row("service: upload, split, frame tasks, outputs in S3 (2 workers)", path.name, measured,
               seconds, note=f"job {job['state']}")


def rows(clips: dict[str, tuple[Path, ScanSpec]], frames: int) -> list[Callable[[], Row]]:
    """The measurements, in the order printed (each a thunk, so they run one at a time)."""
    every = FrameSelection()
    k = max(1, frames // 10)
    out: list[Callable[[], Row]] = []
    for path, spec in clips.values():
        out.append(lambda p=path: decode_only(p))
        out.append(lambda p=path, s=spec: engine(p, s, every, "engine, every frame"))
    path, spec = clips["MJPG"]
    out.append(lambda: engine(path, spec, FrameSelection(sharpest=k), f"engine, sharpest {k} of {frames}"))
    out.append(lambda: through_service(path, spec))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=60, help="frames in each clip")
    parser.add_argument("--poses", type=int, default=6, help="distinct renders, cycled")
    args = parser.parse_args()
    console = Console(width=160)
    codecs = ["MJPG"] + (["h264"] if importlib.util.find_spec("imageio_ffmpeg") else [])
    if "h264" not in codecs:
        console.print("imageio-ffmpeg is not installed: no H.264 clip (pip install -e .[test])")
    with tempfile.TemporaryDirectory() as tmp:
        clips = {c: make_clip(Path(tmp), c, args.frames, args.poses) for c in codecs}
        table = Table(title=f"{SIZE[0]}x{SIZE[1]} video, {args.frames} frames: frames per second")
        stages = ("select", "decode", "scan", "write")
        for col in ("path", "clip", "frames", "seconds", "frames/s", "ms/frame",
                    *(f"{s} ms" for s in stages), "note"):
            table.add_column(col)
        for measure in rows(clips, args.frames):
            r = measure()
            table.add_row(r.what, r.clip, str(r.frames), f"{r.seconds:.2f}", f"{r.fps:.1f}",
                          f"{1000 / r.fps:.0f}",
                          *(f"{r.stages_ms[s]:.0f}" if s in r.stages_ms else "-" for s in stages),
                          r.note)
        console.print(table)
        console.print("stage columns: milliseconds per frame measured; select includes the probe "
                      "(and the sharpness pass over every candidate for the sharpest row)")


if __name__ == "__main__":
    main()

"""Engine benchmark: figures measured side by side in one run.

1. Scan plus cloud (plan, scan, assemble; no decoding or writing) of 1280x1024 photos, our
   default method and the paper's, against the paper's 15-35 s per cloud (target: < 50 ms).
2. Writers on 4,000,000 points: our CSV against numpy.savetxt (target >= 5x faster) and our
   binary PLY against Open3D's write_point_cloud (target: no slower).
3. Peak memory of a whole 4-million-point job (decode, scan, volume cloud, CSV and PLY) in a
   fresh process.

Run: .venv/bin/python benchmarks/engine.py [--runs N] [--points N]
"""

from __future__ import annotations

import os

# Taken before anything else is imported: OpenCV, polars and Open3D change the environment
# (library paths, allocator settings) when imported, and the memory case must not inherit that.
_CLEAN_ENV = dict(os.environ)

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from prismcore import ScanSpec, run_scan
from prismsynth import Box, render_front_view, render_oblique_view, render_side_view, save_image

sys.path.insert(0, str(Path(__file__).parent))
import writers_bench

PAPER_SECONDS = (15.0, 35.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def _clicks(points: dict, names: tuple[str, ...]) -> list:
    return [list(np.rint(points[n])) for n in names]


def _scenes() -> list[tuple[str, ScanSpec, list[np.ndarray]]]:
    box = Box(120.0, 80.0, 60.0)
    oblique = render_oblique_view(box, seed=1)
    front, side = render_front_view(box, seed=2), render_side_view(box, seed=3)
    one = ScanSpec(image="x", points=_clicks(oblique.points, NAMES), focal_px=oblique.focal_px,
                   scale={"kind": "pinhole", "distance_mm": oblique.distance_mm})
    two = ScanSpec(image="f", side_image="s",
                   points=_clicks(front.points, NAMES[:3]) + _clicks(side.points, NAMES[3:5]),
                   scale={"kind": "mm_per_px", "front": front.mm_per_px, "side": side.mm_per_px})
    return [("one oblique photo (p1-p7, focal)", one, [oblique.image]),
            ("two square photos (mm/px)", two, [front.image, side.image])]


def time_engine(spec: ScanSpec, images: list[np.ndarray], runs: int) -> dict:
    run_scan(spec, *images)  # warm-up
    totals, stages, points = [], [], 0
    for _ in range(runs):
        start = time.perf_counter()
        result = run_scan(spec, *images)
        totals.append((time.perf_counter() - start) * 1000)
        stages.append(result.report.timings_ms)
        points = result.report.points
    per_stage = {k: float(np.median([s[k] for s in stages])) for k in stages[0]}
    return {"median_ms": float(np.median(totals)), "p90_ms": float(np.percentile(totals, 90)),
            "stages": per_stage, "points": points}


# Runs in a fresh interpreter that imports only what a job needs, so its peak RSS is the job's.
_MEMORY_CASE = """
import json, resource, sys
from pathlib import Path
from prismcore import ScanSpec, run_scan
from prismcore.io.images import load_image
from prismcore.outputs.writers import write_csv, write_ply
image, spec_json, out = sys.argv[1:4]
before = int(open("/proc/self/statm").read().split()[1]) * resource.getpagesize() / 2**20
result = run_scan(ScanSpec.model_validate_json(spec_json), load_image(image))
write_csv(Path(out) / "cloud.csv", result.cloud.points)
write_ply(Path(out) / "cloud.ply", result.cloud.points, result.cloud.colors)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"points": result.report.points, "peak_rss_mb": peak, "after_imports_mb": before}))
"""


def measure_memory() -> dict:
    box = Box(120.0, 80.0, 60.0)
    near = render_oblique_view(box, seed=1)
    # A volume cloud's size goes as 1/distance^3: 2.44x the default distance gives ~4M points.
    scene = render_oblique_view(box, seed=1, distance_mm=near.distance_mm * 2.44)
    spec = ScanSpec(image="x", points=_clicks(scene.points, NAMES), focal_px=scene.focal_px,
                    cloud="volume", scale={"kind": "pinhole", "distance_mm": scene.distance_mm})
    with tempfile.TemporaryDirectory() as tmp:
        save_image(scene, Path(tmp) / "box.png")
        out = subprocess.run(
            [sys.executable, "-c", _MEMORY_CASE, str(Path(tmp) / "box.png"),
             spec.model_dump_json(), tmp], capture_output=True, text=True, check=True,
            env=_CLEAN_ENV)
    return json.loads(out.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--points", type=int, default=4_000_000)
    args = parser.parse_args()
    console = Console(width=160)

    table = Table(title="Scan + cloud of a 1280x1024 photo (engine only; median of "
                        f"{args.runs} runs)")
    for col in ("scene", "method", "points", "median ms", "p90 ms", "stages (median ms)",
                "vs paper 15-35 s"):
        table.add_column(col)
    for name, spec, images in _scenes():
        for method in ("default", "paper"):
            r = time_engine(spec.model_copy(update={"method": method}), images, args.runs)
            stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stages"].items())
            speedup = (f"{PAPER_SECONDS[0] * 1000 / r['median_ms']:,.0f}x-"
                       f"{PAPER_SECONDS[1] * 1000 / r['median_ms']:,.0f}x faster")
            table.add_row(name, method, f"{r['points']:,}", f"{r['median_ms']:.1f}",
                          f"{r['p90_ms']:.1f}", stages, speedup)
    console.print(table)

    rows = writers_bench.run(args.points)
    table = Table(title=f"Writers on {args.points:,} points (same points, one run)")
    for col in ("writer", "seconds", "baseline", "baseline / ours"):
        table.add_column(col)
    for row in rows:
        ratio = row.get("ratio_vs_baseline")
        table.add_row(row["name"], f"{row['seconds']:.3f}", str(row.get("baseline") or "-"),
                      f"{ratio:.1f}x" if ratio else "-")
    console.print(table)

    mem = measure_memory()
    console.print(f"Peak memory of a whole {mem['points']:,}-point job (decode, scan, volume "
                  f"cloud, CSV + PLY): {mem['peak_rss_mb']:.0f} MB peak RSS, of which "
                  f"{mem['after_imports_mb']:.0f} MB is the interpreter and libraries; "
                  f"the cloud itself is {mem['points'] * 15 / 2**20:.0f} MB")


if __name__ == "__main__":
    main()

"""Issue 28's figures, side by side in one run: each beside its target and the figure before.

    .venv/bin/python benchmarks/speed.py            # every figure, now and at --base (~10 min)
    .venv/bin/python benchmarks/speed.py --quick    # the quick subset (~1 min)
    .venv/bin/python benchmarks/speed.py --only engine.sample.total,out.overlay --no-base

Every figure is measured twice, in fresh child processes of this same script: once on this tree
("now") and once on the tree of `--base` (default BASE_COMMIT, the engine as issue 28 found it),
checked out with `git worktree add --detach` under /tmp and imported first through PYTHONPATH
(a folder of links named as pyproject's package-dir maps them: prismcore, prismsynth, prism_cli,
...; the child prints which prismcore it imported, and the run stops when it is not the base's).
The same measuring code runs on both sides; a figure whose code the base lacks prints n/a there.

Single-threaded figures run with cv2.setNumThreads(1) and one BLAS/OpenMP thread; times are CPU
time (time.process_time) medians over repeats: the machine is shared, and CPU time is what a
factory batch pays. A figure is a function registered with @figure; it gets a `Ctx` (quick or
not, the tree measured, a cache shared by the figures of one child) and returns a number in its
unit, or a `Measured` (number and a note), or None (not measured). To add one: write the
function beside the others in its group, nothing else.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# The engine as issue 28 found it (the subpackage layout, before any speed work).
BASE_COMMIT = "773c537"
SAMPLE = ROOT / "samples" / "box.jpg"
SAMPLE_POINTS = "395,293 943,331 919,761 943,331 1035,298 411,647 1009,660"
SAMPLE_FLAGS = ["--focal-px", "1400", "--width-mm", "120"]
# pyproject's [tool.setuptools] package-dir: package -> folder in a tree.
PACKAGES = {"prismcore": "shared/prismcore", "prismsynth": "shared/prismsynth", "prism_cli": "services/cli",
            "prism_common": "services/common", "prism_api": "services/api", "prism_worker": "services/worker"}
# The writers keep their own threads (polars' CSV): their earlier figures were measured so.
SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------

@dataclass
class Measured:
    value: float | None
    note: str = ""


@dataclass
class Ctx:
    quick: bool
    tree: Path  # the tree measured (this checkout, or the base's worktree)
    cache: dict[str, Any] = field(default_factory=dict)

    def once(self, key: str, make: Callable[[], Any]) -> Any:
        """`make()` once per child process (several figures read one measurement)."""
        if key not in self.cache:
            self.cache[key] = make()
        return self.cache[key]


@dataclass
class Figure:
    key: str
    group: str
    label: str
    target: str  # in words, e.g. "<= 50"
    unit: str
    fn: Callable[[Ctx], float | Measured | None]
    quick: bool  # part of --quick
    limit: float | None  # the target as a number (met when value <= limit; >= when `at_least`)
    at_least: bool = False


FIGURES: list[Figure] = []


def figure(key: str, group: str, label: str, *, unit: str, target: str = "",
           limit: float | None = None, at_least: bool = False,
           quick: bool = True) -> Callable[[Callable[[Ctx], Any]], Callable[[Ctx], Any]]:
    def register(fn: Callable[[Ctx], Any]) -> Callable[[Ctx], Any]:
        FIGURES.append(Figure(key, group, label, target, unit, fn, quick, limit, at_least))
        return fn
    return register


# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------

def single_thread() -> None:
    import cv2
    cv2.setNumThreads(1)


@contextmanager
def cpu_clock() -> Iterator[None]:
    """The engine's own stage timings (time.perf_counter in the pipeline) read as CPU time."""
    wall = time.perf_counter
    time.perf_counter = time.process_time  # type: ignore[assignment]
    try:
        yield
    finally:
        time.perf_counter = wall  # type: ignore[assignment]


def median_cpu_ms(fn: Callable[[], Any], runs: int, warm: int = 1) -> float:
    for _ in range(warm):
        fn()
    times = []
    for _ in range(runs):
        start = time.process_time()
        fn()
        times.append((time.process_time() - start) * 1000)
    return statistics.median(times)


def sample_spec(**extra: Any) -> Any:
    from prismcore import ScanSpec
    points = [[float(v) for v in p.split(",")] for p in SAMPLE_POINTS.split()]
    return ScanSpec(image=str(SAMPLE), points=points, focal_px=1400.0,
                    scale={"kind": "edge", "edge": "width", "length_mm": 120.0}, **extra)


ENGINE_STAGES = ("refine", "measure", "scan", "assemble")


def engine_runs(ctx: Ctx, name: str, spec: Any, image: Any) -> dict[str, float]:
    """Median CPU ms per stage and in all (run_scan: refine + measure + scan + assemble), and
    the dimensions (mm) of the last run."""
    def make() -> dict[str, float]:
        from prismcore import run_scan
        single_thread()
        runs = 5 if ctx.quick else 15
        with cpu_clock():
            run_scan(spec, image)
            totals, stages = [], []
            result = None
            for _ in range(runs):
                start = time.process_time()
                result = run_scan(spec, image)
                totals.append((time.process_time() - start) * 1000)
                stages.append(report_json(result.report)["timings_ms"])
        out = {k: statistics.median(s.get(k, 0.0) for s in stages) for k in ENGINE_STAGES}
        out["total"] = statistics.median(totals)
        assert result is not None
        out.update({f"dim.{k}": float(v) for k, v in report_json(result.report)["dimensions"].items()
                    if isinstance(v, int | float)})
        return out
    return ctx.once(f"engine:{name}", make)


def sample_engine(ctx: Ctx) -> dict[str, float]:
    from prismcore.io.images import load_image
    return engine_runs(ctx, "sample", sample_spec(), load_image(SAMPLE))


def photo_like_engine(ctx: Ctx) -> dict[str, float]:
    """The engine on photo-like oblique renders (1280x1024, clicked as a user would, one known
    edge, no focal length): the median over scenes of each scene's median."""
    def make() -> dict[str, float]:
        from prismcore import ScanSpec
        from prismsynth import photo_like_scene
        seeds = range(3) if ctx.quick else range(8)
        per: list[dict[str, float]] = []
        for seed in seeds:
            p = photo_like_scene(seed, image_size=(1280, 1024))
            clicks = [list(map(float, p.clicks[f"p{i}"])) for i in range(1, 8)]
            spec = ScanSpec(image="photo.jpg", points=clicks,
                            scale={"kind": "edge", "edge": p.known_edge, "length_mm": p.known_length_mm})
            per.append(engine_runs(ctx, f"photo_like:{seed}", spec, p.image))
        return {k: statistics.median(r[k] for r in per) for k in (*ENGINE_STAGES, "total")}
    return ctx.once("engine:photo_like", make)


def prism_command(tree: Path) -> list[str]:
    """`prism` as the tree's own entry point (pyproject: prism = prism_cli.main:app)."""
    return [sys.executable, "-c", "import sys; from prism_cli.main import app; sys.argv[0] = 'prism'; app()"]


def run_child_process(cmd: list[str]) -> tuple[float, float, subprocess.CompletedProcess[str]]:
    """Wall and CPU seconds (the child's user + system) of one command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done


def sample_command(ctx: Ctx) -> dict[str, float]:
    """`prism scan` of the sample with the default outputs, in a fresh process: the process's CPU
    and wall ms, and the report's own timings (load, engine stages, writers, total)."""
    def make() -> dict[str, float]:
        runs = 3 if ctx.quick else 7
        cpus, walls, reports = [], [], []
        for _ in range(runs):
            with tempfile.TemporaryDirectory(prefix="speed_scan_") as out:
                cmd = [*prism_command(ctx.tree), "scan", str(SAMPLE), "--points", SAMPLE_POINTS,
                       *SAMPLE_FLAGS, "--out", out]
                wall, cpu, done = run_child_process(cmd)
                if done.returncode != 0:
                    raise RuntimeError(f"prism scan failed: {done.stderr[-500:]}")
                reports.append(json.loads((Path(out) / "report.json").read_text())["timings_ms"])
                cpus.append(cpu * 1000)
                walls.append(wall * 1000)
        out = {"cpu_ms": statistics.median(cpus), "wall_ms": statistics.median(walls)}
        for key in reports[0]:
            out[f"t.{key}"] = statistics.median(r.get(key, 0.0) for r in reports)
        return out
    return ctx.once("command:sample", make)


# ---------------------------------------------------------------------------------------------
# 1. The engine (refine + measure + scan + assemble), single-threaded CPU ms
# ---------------------------------------------------------------------------------------------

def _stage(which: Callable[[Ctx], dict[str, float]], key: str) -> Callable[[Ctx], float]:
    return lambda ctx: which(ctx)[key]


for _stage_name in ENGINE_STAGES:
    figure(f"engine.sample.{_stage_name}", "1 engine", f"sample: {_stage_name}", unit="ms")(
        _stage(sample_engine, _stage_name))


@figure("engine.sample.total", "1 engine", "sample: engine (run_scan)", unit="ms",
        target="<= 50 (goal 20)", limit=50.0)
def engine_sample_total(ctx: Ctx) -> float:
    return sample_engine(ctx)["total"]


@figure("engine.photo_like.total", "1 engine", "photo-like oblique renders: engine", unit="ms",
        target="<= 50 (goal 20)", limit=50.0)
def engine_photo_like_total(ctx: Ctx) -> float:
    return photo_like_engine(ctx)["total"]


for _stage_name in ENGINE_STAGES:
    _label = "measure (incl. rounding)" if _stage_name == "measure" else _stage_name
    figure(f"engine.photo_like.{_stage_name}", "1 engine", f"photo-like: {_label}", unit="ms")(
        _stage(photo_like_engine, _stage_name))


def report_json(report: Any) -> dict[str, Any]:
    """A scan's report as report.json's dict, in either tree: a dict before issue 35, a
    `prismcore.report.ScanReport` since (the fields its mode set)."""
    return report if isinstance(report, dict) else report.model_dump(exclude_unset=True)


def _dims(report: dict) -> str:
    dims, sigma = report["dimensions"], report.get("uncertainty") or {}
    return " x ".join(f"{dims[k]:.2f}±{float(sigma.get(k) or 0):.2f}" for k in ("width", "height", "depth"))


@figure("engine.dims", "1 engine", "dimensions (mm, ±1 sigma): sample; photo-like seeds 0-2", unit="mm")
def engine_dims(ctx: Ctx) -> Measured:
    """The answers the timed engine gives, beside the base's: a speed-up must not move them
    beyond their sigma (issue 28 item 1)."""
    from prismcore import ScanSpec, run_scan
    from prismsynth import photo_like_scene
    result, _ = sample_result(ctx)
    out = [f"sample {_dims(report_json(result.report))}"]
    for seed in range(3):
        p = photo_like_scene(seed, image_size=(1280, 1024))
        clicks = [list(map(float, p.clicks[f"p{i}"])) for i in range(1, 8)]
        spec = ScanSpec(image="photo.jpg", points=clicks,
                        scale={"kind": "edge", "edge": p.known_edge, "length_mm": p.known_length_mm})
        out.append(f"{seed}: {_dims(report_json(run_scan(spec, p.image).report))}")
    return Measured(None, "; ".join(out))


# ---------------------------------------------------------------------------------------------
# 2. Outputs
# ---------------------------------------------------------------------------------------------

def sample_result(ctx: Ctx) -> Any:
    """The sample's scan (its cloud and report), made once per child."""
    def make() -> Any:
        from prismcore import run_scan
        from prismcore.io.images import load_image
        image = load_image(SAMPLE)
        return run_scan(sample_spec(), image), image
    return ctx.once("sample_result", make)


def _overlay_encoder() -> tuple[Callable[[np.ndarray], bytes], str]:
    """The tree's default overlay encoder and its format (PNG before issue 28)."""
    from prismcore.outputs import writers
    encode = getattr(writers, "encode_overlay", None)
    if encode is not None:
        fmt = writers.DEFAULT_OVERLAY_FORMAT
        return (lambda rgb: encode(rgb, fmt)), fmt
    return writers.encode_png, "png"


def _overlay_drawer() -> Callable[..., np.ndarray]:
    try:
        from prismcore.outputs.overlay_report import overlay_from_report
    except ImportError:  # before the overlay's split
        from prismcore.outputs.overlay import overlay_from_report  # type: ignore[no-redef]
    return overlay_from_report


def overlay_figures(ctx: Ctx) -> dict[str, float]:
    def make() -> dict[str, float]:
        single_thread()
        result, image = sample_result(ctx)
        draw, (encode, fmt) = _overlay_drawer(), _overlay_encoder()
        runs = 5 if ctx.quick else 15
        drawn = draw(image, result.report, photo="front")
        return {"draw": median_cpu_ms(lambda: draw(image, result.report, photo="front"), runs),
                "encode": median_cpu_ms(lambda: encode(drawn), runs),
                "bytes": float(len(encode(drawn))), "format": fmt}
    return ctx.once("overlay", make)


@figure("out.overlay", "2 outputs", "overlay, default format (draw + encode)", unit="ms",
        target="<= 20", limit=20.0)
def out_overlay(ctx: Ctx) -> Measured:
    o = overlay_figures(ctx)
    return Measured(o["draw"] + o["encode"],
                    f"{o['format']}: draw {o['draw']:.0f} + encode {o['encode']:.0f} ms, "
                    f"{o['bytes'] / 1e6:.2f} MB")


def writer_rows(ctx: Ctx) -> dict[str, dict]:
    def make() -> dict[str, dict]:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import writers_bench
        rows = writers_bench.run(2_000_000 if ctx.quick else 4_000_000, repeat=1 if ctx.quick else 3)
        return {r["name"]: r for r in rows}
    return ctx.once("writers", make)


@figure("out.csv_4m", "2 outputs", "CSV writer, 4 M points (wall, best of 3)", unit="s",
        target="<= 0.63", limit=0.63, quick=False)
def out_csv(ctx: Ctx) -> Measured:
    rows = writer_rows(ctx)
    ours = rows["prismcore.write_csv"]
    return Measured(ours["seconds"], f"{ours['ratio_vs_baseline']:.1f}x numpy.savetxt (earlier: 12x)")


@figure("out.ply_vs_open3d", "2 outputs", "binary PLY writer, 4 M points: Open3D / ours", unit="x",
        target=">= 6.5", limit=6.5, at_least=True, quick=False)
def out_ply(ctx: Ctx) -> Measured:
    rows = writer_rows(ctx)
    ours = rows["prismcore.write_ply (binary)"]
    ratio = ours.get("ratio_vs_baseline")
    return Measured(ratio, f"ours {ours['seconds']:.3f} s" if ratio else "open3d not installed")


def sample_writer_ms(ctx: Ctx, kind: str) -> Measured:
    def make() -> Measured:
        from prismcore.outputs.writers import write_format
        result, _ = sample_result(ctx)
        spec = sample_spec(formats=[kind])
        with tempfile.TemporaryDirectory(prefix="speed_out_") as tmp:
            path = Path(tmp) / f"cloud.{kind}"
            ms = median_cpu_ms(lambda: write_format(kind, path, result.cloud, spec, report=result.report),
                               3 if ctx.quick else 7)
            size = path.stat().st_size
        return Measured(ms, f"{len(result.cloud.points):,} points, {size / 1e6:.1f} MB (CPU)")
    return ctx.once(f"write:{kind}", make)


@figure("out.laz_sample", "2 outputs", "LAZ writer, the sample's cloud", unit="ms", target="<= 60",
        limit=60.0)
def out_laz(ctx: Ctx) -> Measured:
    return sample_writer_ms(ctx, "laz")


@figure("out.laz_floor", "2 outputs", "LAZ: lazrs' compression alone, the sample's cloud", unit="ms",
        target="(the floor of LAZ)")
def out_laz_floor(ctx: Ctx) -> Measured:
    """What the LAZ writer cannot go below on one core: lazrs compressing the sample's points as
    point format 2 (XYZ + RGB, what the writer writes), and format 0 (XYZ alone) for the note;
    the records are built beforehand, as the writer builds them."""
    import lazrs

    from prismcore.outputs.las import COLOR_SCALE, SCALE_M
    result, _ = sample_result(ctx)
    points, colors = result.cloud.points.astype(np.float64), result.cloud.colors
    rgb = np.dtype([("X", "<i4"), ("Y", "<i4"), ("Z", "<i4"), ("intensity", "<u2"), ("bits", "u1"),
                    ("classification", "u1"), ("scan_angle", "i1"), ("user_data", "u1"),
                    ("point_source_id", "<u2"), ("red", "<u2"), ("green", "<u2"), ("blue", "<u2")])
    record = np.zeros(len(points), rgb)  # LAS point format 2, 26 bytes
    for name, axis, sign in (("X", 0, 1.0), ("Y", 2, 1.0), ("Z", 1, -1.0)):
        record[name] = np.rint(sign * points[:, axis] / 1000.0 / SCALE_M)
    for name, channel in (("red", 0), ("green", 1), ("blue", 2)):
        record[name] = colors[:, channel].astype(np.uint16) * COLOR_SCALE
    plain = np.zeros(len(points), np.dtype([(n, rgb.fields[n][0]) for n in rgb.names[:9]]))  # format 0
    for name in plain.dtype.names or ():
        plain[name] = record[name]
    xyz_bytes = plain.tobytes()
    runs = 3 if ctx.quick else 7
    with_rgb = median_cpu_ms(lambda: lazrs.compress_points(lazrs.LazVlr.new_for_compression(2, 0),
                                                           record.tobytes(), False), runs)
    xyz = median_cpu_ms(lambda: lazrs.compress_points(lazrs.LazVlr.new_for_compression(0, 0),
                                                      xyz_bytes, False), runs)
    return Measured(with_rgb, f"format 2 (XYZ + RGB); without the colours (format 0) {xyz:.0f} ms; "
                              "parallel compression spreads it over cores, the CPU stays")


@figure("out.csv_sample", "2 outputs", "CSV writer, the sample's cloud", unit="ms")
def out_csv_sample(ctx: Ctx) -> Measured:
    return sample_writer_ms(ctx, "csv")


@figure("out.ply_sample", "2 outputs", "PLY writer, the sample's cloud", unit="ms")
def out_ply_sample(ctx: Ctx) -> Measured:
    return sample_writer_ms(ctx, "ply")


def in_command(ctx: Ctx) -> dict[str, float]:
    """What `prism scan` of the sample does after its imports, in this process, CPU ms: decode,
    engine, the default outputs (CSV, PLY) and the overlay in the tree's default format."""
    def make() -> dict[str, float]:
        from prismcore import run_scan
        from prismcore.io.images import load_image
        from prismcore.outputs.writers import write_format
        single_thread()
        spec = sample_spec(formats=["csv", "ply"])
        draw, (encode, _) = _overlay_drawer(), _overlay_encoder()
        parts: dict[str, list[float]] = {"load": [], "engine": [], "writers": [], "overlay": []}
        with tempfile.TemporaryDirectory(prefix="speed_cmd_") as tmp:
            for i in range(4 if ctx.quick else 8):
                t0 = time.process_time()
                image = load_image(SAMPLE)
                t1 = time.process_time()
                result = run_scan(spec, image)
                t2 = time.process_time()
                for kind in spec.formats:
                    write_format(kind, Path(tmp) / f"cloud.{kind}", result.cloud, spec, report=result.report)
                t3 = time.process_time()
                (Path(tmp) / "overlay").write_bytes(encode(draw(image, result.report, photo="front")))
                t4 = time.process_time()
                if i:  # the first is a warm-up
                    for key, start, end in (("load", t0, t1), ("engine", t1, t2), ("writers", t2, t3),
                                            ("overlay", t3, t4)):
                        parts[key].append((end - start) * 1000)
        return {k: statistics.median(v) for k, v in parts.items()}
    return ctx.once("in_command", make)


@figure("cmd.scan_inside", "2 outputs", "prism scan of the sample (default outputs) / engine", unit="x",
        target="<= 3", limit=3.0)
def cmd_scan_ratio(ctx: Ctx) -> Measured:
    t = in_command(ctx)
    whole = sum(t.values())
    return Measured(whole / t["engine"], f"{whole:.0f} ms: load {t['load']:.0f}, engine {t['engine']:.0f}, "
                                         f"CSV+PLY {t['writers']:.0f}, overlay {t['overlay']:.0f} (CPU)")


# ---------------------------------------------------------------------------------------------
# 3. The command itself (the CLI engineer's)
# ---------------------------------------------------------------------------------------------

# A typer app of two commands, its --help: what typer and rich cost alone, the floor of prism --help.
_TYPER_FLOOR = """import typer
app = typer.Typer(add_completion=False, help="x")
app.command()(lambda x: None)
@app.command()
def b(y: int = 1) -> None:
    \"\"\"B.\"\"\"
app()
"""


def help_runs(ctx: Ctx) -> dict[str, float]:
    """`prism --help` in fresh processes: median wall and CPU ms; and the typer floor's CPU."""
    def make() -> dict[str, float]:
        runs = 5 if ctx.quick else 11
        walls, cpus, floor = [], [], []
        for _ in range(runs):
            wall, cpu, done = run_child_process([*prism_command(ctx.tree), "--help"])
            if done.returncode != 0:
                raise RuntimeError(f"prism --help failed: {done.stderr[-300:]}")
            walls.append(wall * 1000)
            cpus.append(cpu * 1000)
            floor.append(run_child_process([sys.executable, "-c", _TYPER_FLOOR, "--help"])[1] * 1000)
        return {"wall": statistics.median(walls), "cpu": statistics.median(cpus),
                "floor": statistics.median(floor)}
    return ctx.once("help", make)


@figure("cmd.help", "3 command", "prism --help (process CPU)", unit="ms", target="<= 200", limit=200.0)
def cmd_help(ctx: Ctx) -> Measured:
    t = help_runs(ctx)
    return Measured(t["cpu"], f"a bare 2-command typer app's --help: {t['floor']:.0f} ms CPU")


@figure("cmd.help_wall", "3 command", "prism --help (wall; the machine's load adds to it)", unit="ms",
        target="<= 200", limit=200.0)
def cmd_help_wall(ctx: Ctx) -> Measured:
    return Measured(help_runs(ctx)["wall"], f"load average {os.getloadavg()[0]:.1f}")


@figure("cmd.scan_fixed", "3 command", "prism scan: fixed cost (process CPU - in-command work)", unit="ms",
        target="<= 300", limit=300.0)
def cmd_scan_fixed(ctx: Ctx) -> Measured:
    process = sample_command(ctx)["cpu_ms"]
    work = sum(in_command(ctx).values())
    return Measured(process - work, f"process {process:.0f} ms CPU, its work {work:.0f} ms")


# What a photo scan imports, each in fresh processes (CPU ms beyond what it is added to): what
# the fixed cost is made of. The last is everything `prism scan` of a photo imports, less Python.
_IMPORTS = (("numpy + OpenCV", "", "import numpy, cv2"),
            ("scipy.optimize (box fit's least_squares)", "import numpy", "import numpy, scipy.optimize"),
            ("polars (CSV)", "import numpy", "import numpy, polars"),
            ("pydantic (the spec)", "", "import pydantic"),
            ("typer + rich", "", "import typer, rich.console"),
            ("all a photo scan imports", "", "import prism_cli.main, prism_cli.outputs, "
             "prismcore.locate.auto_points, prismcore.io.exif, prismcore.outputs.writers"))


def import_costs(ctx: Ctx) -> dict[str, float]:
    def make() -> dict[str, float]:
        runs = 3 if ctx.quick else 7
        cpu: dict[str, float] = {}
        for code in {c for _, before, after in _IMPORTS for c in (before, after)}:
            cmd = [sys.executable, "-c", code or "pass"]
            cpu[code] = statistics.median(run_child_process(cmd)[1] * 1000 for _ in range(runs))
        return {label: cpu[after] - cpu[before] for label, before, after in _IMPORTS}
    return ctx.once("imports", make)


@figure("cmd.scan_imports", "3 command", "prism scan: its imports (process CPU less bare Python)", unit="ms",
        target="(fixed cost's floor)")
def cmd_scan_imports(ctx: Ctx) -> Measured:
    t = import_costs(ctx)
    whole = t.pop("all a photo scan imports")
    return Measured(whole, "; ".join(f"{k} {v:.0f}" for k, v in t.items()))


# ---------------------------------------------------------------------------------------------
# 4. Several views, the search, the worker (the joint-fit / search engineer's)
# ---------------------------------------------------------------------------------------------

# The joint fit's cases: (seed, views) of prismsynth.views.photo_like_views at 1280x1024 (seed 0
# has no 30 poses far enough apart: seed 1 for 30).
JOINT_CASES = {3: 0, 10: 0, 30: 1}


def joint_views(views: int) -> dict[str, Any]:
    """The renders of one joint-fit case, drawn once per machine (both trees fit the same
    pixels: the renders are the fixture, not what is measured): images, clicks, the known edge
    and the true box."""
    import numpy as np
    seed = JOINT_CASES[views]
    cache = Path(tempfile.gettempdir()) / f"speed-joint-views-{seed}-{views}.npz"
    if not cache.exists():
        from prismsynth.views import photo_like_views
        scenes = photo_like_views(seed, views, image_size=(1280, 1024))
        p = scenes[0]
        part = cache.with_suffix(".part.npz")
        np.savez(part, images=np.stack([q.image for q in scenes]),
                 clicks=np.array([q.click_list() for q in scenes], dtype=np.float64),
                 truth=np.array([p.box.width_mm, p.box.height_mm, p.box.depth_mm]),
                 edge=np.array(p.known_edge), length=np.array(p.known_length_mm))
        part.rename(cache)
    with np.load(cache) as data:
        return {k: data[k] for k in data.files}


def joint_fit(ctx: Ctx, views: int) -> Measured:
    """CPU s of `fit_views` over `views` views (no focal, one known edge; cv2 single-threaded), and
    in the note the error of the two dimensions the known edge does not set, their 1-sigma and
    the solver's work (nfev)."""
    from prismcore.multiview.joint import View, fit_views
    from prismcore.spec import KnownEdge
    single_thread()
    case = joint_views(views)
    scale = KnownEdge(edge=str(case["edge"]), length_mm=float(case["length"]))  # type: ignore[arg-type]
    given = [View(image, [list(map(float, p)) for p in clicks], name=f"view {k + 1}")
             for k, (image, clicks) in enumerate(zip(case["images"], case["clicks"], strict=True))]
    start = time.process_time()
    result = fit_views(given, scale)
    seconds = time.process_time() - start
    d = result.dimensions
    sigma = d.uncertainty or (0.0, 0.0, 0.0)
    errors = [f"{name} {100 * (got / true - 1):+.2f} % (1s {100 * s / true:.2f})"
              for name, got, s, true in zip(("width", "height", "depth"), (d.width, d.height, d.depth),
                                            sigma, case["truth"], strict=True) if name != str(case["edge"])]
    return Measured(seconds, f"{', '.join(errors)}; nfev {result.nfev}, {len(result.left_out)} left out")


@figure("joint.3", "4 views", "joint fit, 3 views of 1280x1024 (CPU)", unit="s", target="", quick=True)
def joint_3(ctx: Ctx) -> Measured:
    return joint_fit(ctx, 3)


@figure("joint.10", "4 views", "joint fit, 10 views (CPU)", unit="s", target="<= 3", limit=3.0, quick=False)
def joint_10(ctx: Ctx) -> Measured:
    return joint_fit(ctx, 10)


@figure("joint.30", "4 views", "joint fit, 30 views (CPU)", unit="s", target="<= 10", limit=10.0, quick=False)
def joint_30(ctx: Ctx) -> Measured:
    return joint_fit(ctx, 30)


def search_runs(ctx: Ctx) -> dict[str, Any]:
    """`find_points` on clutter scenes (benchmarks/zero_click.py's, 1280x1024), cv2 single-threaded:
    each scene's search CPU ms (its `timings_ms["search_cpu"]`: edges, faces, boxes, fallbacks,
    PnP screen; the corner fits left out) and whether its points lie within 3 px of the box's
    corners (accepted scenes)."""
    def make() -> dict[str, Any]:
        import numpy as np

        from prismcore.locate.search import find_points
        from prismsynth.scenes import clutter_scene
        single_thread()
        scenes = [clutter_scene(seed) for seed in range(20 if ctx.quick else 60)]
        find_points(scenes[0].image)  # OpenCV's one-time set-up is no photo's cost
        cpu, right, accepted = [], 0, 0
        for scene in scenes:
            found = find_points(scene.image)
            cpu.append(found.timings_ms.get("search_cpu", 0.0))
            if found.ok and found.points is not None:
                accepted += 1
                worst = max(float(np.linalg.norm(scene.vertices_px - np.asarray(xy), axis=1).min())
                            for xy in found.points.as_dict().values())
                right += worst <= 3.0
        worst_at = int(np.argmax(cpu))
        return {"cpu": cpu, "right": right, "accepted": accepted, "worst_seed": worst_at}
    return ctx.once("search", make)


@figure("search.median", "4 views", "zero-click search, median (CPU)", unit="ms", target="")
def search_median(ctx: Ctx) -> Measured:
    r = search_runs(ctx)
    return Measured(statistics.median(r["cpu"]), f"{len(r['cpu'])} clutter scenes: {r['accepted']} accepted, "
                                                 f"{r['right']} of them within 3 px")


@figure("search.worst", "4 views", "zero-click search, worst (CPU)", unit="ms", target="<= 150", limit=150.0)
def search_worst(ctx: Ctx) -> Measured:
    r = search_runs(ctx)
    cpu = sorted(r["cpu"])
    return Measured(cpu[-1], f"scene {r['worst_seed']}; p90 {cpu[int(0.9 * (len(cpu) - 1))]:.0f} ms")


def worker_parts(ctx: Ctx) -> dict[str, Any]:
    """The worker's own work per photo, in this process (no Celery, Redis or uploads): the
    service's default outputs (CSV, PLY), the preview, the overlay as the worker stores it, the
    report; median CPU ms per photo over the throughput model's 1280x1024 photos (the first
    round a warm-up), beside the engine's."""
    def make() -> dict[str, Any]:
        import io

        sys.path.insert(0, str(ctx.tree / "benchmarks"))
        from throughput_model import _photos

        from prism_worker import artifacts
        from prismcore import ScanSpec, run_scan
        from prismcore.io.images import load_image
        from prismcore.outputs import writers
        from prismcore.scan.cloud import decimate
        single_thread()
        draw, fmt = _overlay_drawer(), getattr(artifacts, "OVERLAY_FORMAT", "png")
        # The overlay shrunk as the worker stores it: prismcore.outputs.sink's since the output sink,
        # the worker's own in older checkouts (--before).
        try:
            from prismcore.outputs.sink import display_size

            def _display_size(picture: np.ndarray) -> np.ndarray:
                return display_size(picture, artifacts.OVERLAY_MAX_SIDE)
        except ImportError:
            _display_size = artifacts._display_size
        rounds: list[dict[str, float]] = []
        for _ in range(3 if ctx.quick else 4):
            for data, item in _photos(4):
                spec = ScanSpec.model_validate({"image": "x", **item})
                marks = [("", time.process_time())]
                image = load_image(data)
                marks.append(("decode", time.process_time()))
                result = run_scan(spec, image)
                marks.append(("engine", time.process_time()))
                for kind in spec.formats:
                    writers.write_format(kind, io.BytesIO(), result.cloud, spec, report=result.report,
                                         images=[image])
                marks.append(("outputs", time.process_time()))
                preview = decimate(result.cloud)
                writers.write_ply(io.BytesIO(), preview.points, preview.colors)
                marks.append(("preview", time.process_time()))
                picture = _display_size(draw(image, result.report, photo="front"))
                writers.encode_overlay(picture, fmt) if fmt != "png" else writers.encode_png(picture)
                marks.append(("overlay", time.process_time()))
                json.dumps(report_json(result.report), indent=2).encode()
                marks.append(("report", time.process_time()))
                rounds.append({name: (t - marks[k][1]) * 1000 for k, (name, t) in enumerate(marks[1:])})
        kept = rounds[4:]
        return {"format": fmt} | {k: statistics.median(r[k] for r in kept) for k in kept[0]}
    return ctx.once("worker_parts", make)


@figure("worker.own_floor", "4 views", "worker's own steps + engine / engine, in process", unit="x",
        target="(the ratio's floor)")
def worker_own_floor(ctx: Ctx) -> Measured:
    t = worker_parts(ctx)
    fmt = t.pop("format")
    whole = sum(t.values())
    return Measured(whole / t["engine"], ", ".join(f"{k} {v:.0f}" for k, v in t.items())
                    + f" ms CPU (overlay as {fmt}); the stack (Celery, Redis, uploads) comes on top")


@figure("worker.ratio", "4 views", "worker CPU per photo / engine CPU", unit="x", target="<= 2",
        limit=2.0, quick=False)
def worker_ratio(ctx: Ctx) -> Measured:
    """benchmarks/worker_cost.py of the tree measured: 16 photos (8 distinct, 1280x1024, a scale)
    as jobs of 8 through the real stack (redis, SeaweedFS, the API, a 2-process worker), the
    service's default outputs; the worker's CPU per photo over the engine's in-process CPU."""
    sys.path.insert(0, str(ctx.tree / "benchmarks"))
    import worker_cost  # the tree's own
    from throughput_model import _photos
    distinct = _photos(8)
    _, engine = worker_cost.engine_cost(distinct, 3)
    worker = worker_cost.worker_cost([distinct[i % 8] for i in range(16)], 8, None, None)
    return Measured(worker / engine, f"worker {worker:.0f} ms CPU per photo, engine {engine:.0f} ms")


# ---------------------------------------------------------------------------------------------
# Children, the base tree, the table
# ---------------------------------------------------------------------------------------------

def child_main(keys: list[str], quick: bool, tree: Path, out: Path) -> None:
    """Measure `keys` in this process; write {key: [value, note]} as JSON to `out`."""
    import prismcore
    ctx = Ctx(quick=quick, tree=tree)
    results: dict[str, Any] = {"__prismcore__": str(Path(prismcore.__file__).resolve())}
    by_key = {f.key: f for f in FIGURES}
    for key in keys:
        try:
            got = by_key[key].fn(ctx)
        except Exception as exc:  # a figure the tree cannot give prints n/a
            got = Measured(None, f"n/a: {type(exc).__name__}: {str(exc)[:80]}")
        if not isinstance(got, Measured):
            got = Measured(None if got is None else float(got))
        results[key] = [got.value, got.note]
    out.write_text(json.dumps(results))


def base_tree(rev: str) -> tuple[Path, Path]:
    """The base's worktree (made once) and a folder of links to its packages for PYTHONPATH."""
    sha = subprocess.run(["git", "rev-parse", "--short=10", rev], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout.strip()
    tree = Path(tempfile.gettempdir()) / f"speed-base-{sha}"
    if not tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), sha], cwd=ROOT, check=True,
                       capture_output=True)
    links = tree.parent / f"speed-base-{sha}-path"
    links.mkdir(exist_ok=True)
    for package, folder in PACKAGES.items():
        link = links / package
        if not link.exists():
            link.symlink_to(tree / folder)
    return tree, links


def run_side(keys: list[str], quick: bool, tree: Path, pythonpath: Path | None) -> dict[str, Any]:
    env = {**os.environ, **SINGLE_THREAD_ENV}
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    with tempfile.TemporaryDirectory(prefix="speed_child_") as tmp:
        out = Path(tmp) / "figures.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--child", ",".join(keys), "--tree", str(tree),
               "--out", str(out)] + (["--quick"] if quick else [])
        subprocess.run(cmd, env=env, check=True, cwd=tree)
        results: dict[str, Any] = json.loads(out.read_text())
    expected = (tree / PACKAGES["prismcore"]).resolve()
    if not results["__prismcore__"].startswith(str(expected)):
        sys.exit(f"the child imported {results['__prismcore__']}, not {expected}")
    return results


def _fmt(value: float | None, unit: str) -> str:
    if value is None:
        return "-"
    if unit == "s":
        return f"{value:.2f} s"
    if unit == "x":
        return f"{value:.1f}x"
    return f"{value:.1f} {unit}"


def print_table(rows: list[tuple[Figure, list | None, list | None]], base_name: str) -> None:
    from rich.console import Console
    from rich.table import Table
    table = Table(title="Issue 28: speed figures (CPU time, single-threaded, medians)")
    for col in ("group", "figure", "target", f"before ({base_name})", "now", "met", "note"):
        table.add_column(col)
    for fig, now, before in rows:
        value = now[0] if now else None
        met = "-"
        if value is not None and fig.limit is not None:
            ok = value >= fig.limit if fig.at_least else value <= fig.limit
            met = "yes" if ok else "NO"
        notes = "; ".join(n for n in ((now or [None, ""])[1], (before or [None, ""])[1] and
                                      f"before: {(before or [None, ''])[1]}") if n)
        table.add_row(fig.group, fig.label, fig.target, _fmt(before[0] if before else None, fig.unit),
                      _fmt(value, fig.unit), met, notes)
    Console(width=200).print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="the quick subset (~1 min)")
    parser.add_argument("--only", help="comma-separated figure keys (see --list)")
    parser.add_argument("--list", action="store_true", help="list the figures' keys")
    parser.add_argument("--base", default=BASE_COMMIT, help=f"commit measured as 'before' ({BASE_COMMIT})")
    parser.add_argument("--no-base", action="store_true", help="measure this tree only")
    parser.add_argument("--json", type=Path, help="also write every figure here as JSON")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--tree", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        child_main(args.child.split(","), args.quick, args.tree, args.out)
        return
    if args.list:
        for f in FIGURES:
            print(f"{f.key:28} {f.group:10} {f.label}{'' if f.quick else '  (not in --quick)'}")
        return
    figures = [f for f in FIGURES if (not args.quick or f.quick)]
    if args.only:
        wanted = set(args.only.split(","))
        figures = [f for f in FIGURES if f.key in wanted]
    keys = [f.key for f in figures]
    now = run_side(keys, args.quick, ROOT, None)
    before: dict[str, Any] = {}
    if not args.no_base:
        tree, links = base_tree(args.base)
        before = run_side(keys, args.quick, tree, links)
    print_table([(f, now.get(f.key), before.get(f.key)) for f in figures],
                "-" if args.no_base else args.base)
    if args.json:
        args.json.write_text(json.dumps({"now": now, "before": before, "base": args.base}, indent=1))


if __name__ == "__main__":
    main()

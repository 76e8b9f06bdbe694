"""Point-cloud writer benchmark: our CSV and PLY writers against numpy.savetxt and Open3D.

    python benchmarks/writers_bench.py [--points N] [--repeat R]

:func:`run` is quiet and returns one dict per writer, so the project's main benchmark can
import it; :func:`main` prints a table. Every writer gets the same seeded random cloud
(float32 points, as the engine makes them, and uint8 colours) and writes a file in a temporary
directory, which is removed afterwards.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

try:
    from prismcore.outputs.writers import write_csv, write_ply
except ImportError:  # the project is not pip-installed: use the tree's copy
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shared"))
    from prismcore.outputs.writers import write_csv, write_ply

__all__ = ["main", "make_cloud", "run"]

SAVETXT = "numpy.savetxt(fmt='%.3f')"
OPEN3D = "open3d.write_point_cloud (binary)"
_MB = 1024 * 1024


def make_cloud(n_points: int, seed: int = 2024) -> tuple[np.ndarray, np.ndarray]:
    """Seeded float32 points in a 500 mm cube centred on the origin, and uint8 colours."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-250.0, 250.0, (n_points, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (n_points, 3), dtype=np.uint8)
    return points, colors


def run(n_points: int = 4_000_000, *, repeat: int = 1, seed: int = 2024) -> list[dict]:
    """Time each writer on the same cloud; return rows, printing nothing.

    Each row: ``name``; ``seconds`` (best of ``repeat``); ``baseline`` (the name of the row it is
    compared with, or None); ``ratio_vs_baseline`` (baseline seconds / these seconds, so 5.0
    means five times faster; 1.0 on the baselines themselves, None without a baseline);
    ``bytes`` (file size); ``points``; and for our writers ``peak_rss_mb`` (resident memory
    high-water mark above the resident size just before the call, from /proc/self/status;
    None where that cannot be reset) and ``peak_traced_mb`` (tracemalloc's peak: Python and
    numpy allocations, not polars' Rust ones). The Open3D row (present only when open3d imports)
    also has ``prepare_seconds``, the untimed conversion to an Open3D PointCloud.
    """
    if n_points < 0 or repeat < 1:
        raise ValueError(f"need n_points >= 0 and repeat >= 1, got {n_points}, {repeat}")
    points, colors = make_cloud(n_points, seed)
    ours: list[tuple[str, str | None, Callable[[Path], Any]]] = [
        ("prismcore.write_csv", SAVETXT, lambda p: write_csv(p, points)),
        ("prismcore.write_ply (binary)", OPEN3D, lambda p: write_ply(p, points, colors)),
        ("prismcore.write_ply (ascii)", None, lambda p: write_ply(p, points, colors, ascii=True)),
    ]
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="writers_bench_") as tmp:
        folder = Path(tmp)
        # Warm up (polars starts its thread pool on first use), then ours first, so the
        # baselines' large buffers do not sit in the resident set already.
        small_points, small_colors = make_cloud(1000, seed)
        write_csv(folder / "warm.csv", small_points, small_colors)
        write_ply(folder / "warm.ply", small_points, small_colors, ascii=True)
        for index, (name, baseline, fn) in enumerate(ours):
            path = folder / f"ours{index}"
            seconds, rss = _best(fn, path, repeat)
            row = _row(name, baseline, seconds, path, n_points)
            row["peak_rss_mb"] = None if rss is None else rss / _MB
            row["peak_traced_mb"] = _traced_peak(fn, path) / _MB
            rows.append(row)

        path = folder / "savetxt.csv"
        seconds, _ = _best(lambda p: np.savetxt(p, points, fmt="%.3f", delimiter=","), path, repeat)
        rows.append(_row(SAVETXT, None, seconds, path, n_points))

        o3d = _open3d()
        if o3d is not None:
            start = time.perf_counter()
            cloud = o3d.geometry.PointCloud()
            cloud.points = o3d.utility.Vector3dVector(points.astype(np.float64))
            cloud.colors = o3d.utility.Vector3dVector(colors / 255.0)
            prepare = time.perf_counter() - start
            path = folder / "open3d.ply"

            def write_o3d(p: Path) -> None:
                with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
                    if not o3d.io.write_point_cloud(str(p), cloud, write_ascii=False,
                                                    compressed=False, print_progress=False):
                        raise RuntimeError(f"Open3D could not write {p}")

            seconds, _ = _best(write_o3d, path, repeat)
            rows.append(_row(OPEN3D, None, seconds, path, n_points))
            rows[-1]["prepare_seconds"] = prepare
            del cloud

    by_name = {row["name"]: row for row in rows}
    for row in rows:
        base = by_name.get(row["baseline"]) if row["baseline"] else None
        if row["name"] in (SAVETXT, OPEN3D):
            row["ratio_vs_baseline"] = 1.0
        elif base is not None and row["seconds"] > 0:
            row["ratio_vs_baseline"] = base["seconds"] / row["seconds"]
        else:
            row["ratio_vs_baseline"] = None
    return rows


def _row(name: str, baseline: str | None, seconds: float, path: Path, n: int) -> dict:
    return {"name": name, "seconds": seconds, "baseline": baseline, "ratio_vs_baseline": None,
            "bytes": path.stat().st_size, "points": n}


def _best(fn: Callable[[Path], Any], path: Path, repeat: int) -> tuple[float, int | None]:
    """Best time of `repeat` calls, and the largest resident-memory rise seen in them."""
    best, rise = float("inf"), None
    for _ in range(repeat):
        with _rss_rise() as measured:
            start = time.perf_counter()
            fn(path)
            seconds = time.perf_counter() - start
        best = min(best, seconds)
        if measured:
            rise = max(rise or 0, measured[0])
    return best, rise


@contextlib.contextmanager
def _rss_rise() -> Iterator[list[int]]:
    """Yield a list that receives the peak RSS rise (bytes) of the block, if it can be had."""
    result: list[int] = []
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")  # reset the peak (VmHWM) to the current resident size
        before = _status_kb("VmRSS")
    except OSError:
        before = None
    yield result
    if before is not None:
        peak = _status_kb("VmHWM")
        if peak is not None:
            result.append(max(0, peak - before) * 1024)


def _status_kb(field: str) -> int | None:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return None


def _traced_peak(fn: Callable[[Path], Any], path: Path) -> int:
    was_tracing = tracemalloc.is_tracing()
    if not was_tracing:
        tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    try:
        fn(path)
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        if not was_tracing:
            tracemalloc.stop()


def _open3d() -> Any:
    try:
        import open3d
    except (ImportError, OSError):  # not installed, or a system library it needs is missing
        return None
    return open3d


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=4_000_000, help="cloud size")
    parser.add_argument("--repeat", type=int, default=1, help="timed calls per writer (best)")
    args = parser.parse_args(argv)

    from rich.console import Console
    from rich.table import Table

    console = Console()
    with console.status(f"writing {args.points:,} points with each writer..."):
        rows = run(args.points, repeat=args.repeat)

    def num(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    short = {SAVETXT: "savetxt %.3f", OPEN3D: "open3d binary",
             "prismcore.write_csv": "our csv", "prismcore.write_ply (binary)": "our ply binary",
             "prismcore.write_ply (ascii)": "our ply ascii"}
    table = Table(title=f"Point-cloud writers, {args.points:,} points (best of {args.repeat})")
    table.add_column("writer", no_wrap=True)
    for column in ("seconds", "speed-up", "file MB", "RSS+ MB", "traced MB"):
        table.add_column(column, justify="right", no_wrap=True)
    for row in rows:
        ratio = num(row["ratio_vs_baseline"], ".2f")
        if row["baseline"] and row["ratio_vs_baseline"] is not None:
            ratio += " vs " + short[row["baseline"]].split()[0]
        table.add_row(
            short.get(row["name"], row["name"]), f"{row['seconds']:.3f}", ratio,
            f"{row['bytes'] / _MB:.1f}", num(row.get("peak_rss_mb"), ".1f"),
            num(row.get("peak_traced_mb"), ".1f"),
        )
    console.print(table)
    console.print("RSS+: peak resident memory above that before the call; traced: tracemalloc "
                  "peak (Python and numpy allocations)")
    by_name = {row["name"]: row for row in rows}
    csv = by_name["prismcore.write_csv"]
    console.print(f"CSV: savetxt / ours = {csv['ratio_vs_baseline']:.2f}x")
    ply = by_name["prismcore.write_ply (binary)"]
    if ply["ratio_vs_baseline"] is None:
        console.print("PLY: Open3D is not importable here; no comparison")
    else:
        console.print(f"PLY: open3d / ours = {ply['ratio_vs_baseline']:.2f}x")
        console.print(f"(Open3D's untimed conversion to its PointCloud: "
                      f"{by_name[OPEN3D]['prepare_seconds']:.3f} s)")


if __name__ == "__main__":
    main()

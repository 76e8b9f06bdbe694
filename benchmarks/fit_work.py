"""Box-fit work: every free-focal box fit made on the points the zero-click search finds.

For each of N scenes (`prismsynth.scenes.clutter_scene`, as in benchmarks/zero_click.py)
`prismcore.locate.search.find_points` runs (its corner fit plans the points twice), and the points it
found, accepted or not, are planned once more as a scan with no focal length (`plan_scan`).
Every box fit those make is recorded through a wrapper around `prismcore.scan.measure.fit_box` (the
real one runs): its CPU and wall time and its solver evaluations (`BoxFit.nfev`). Points no box
explains once made the fit's starts slide to the focal length's bound for minutes.

Prints per fit: CPU ms, wall ms and evaluations (median, p90, worst), and the slowest scenes.

    .venv/bin/python benchmarks/fit_work.py [--scenes 200] [--seed 0]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from typing import Any

import numpy as np

import prismcore.scan.measure
from prismcore import InputError, ScanSpec, plan_scan
from prismcore.locate.search import find_points
from prismsynth.scenes import clutter_scene

_fits: list[tuple[float, float, int]] = []
_fit_box = prismcore.scan.measure.fit_box


def _recorded(*args: Any, **kwargs: Any) -> Any:
    t0, c0 = time.perf_counter(), time.process_time()
    fit = _fit_box(*args, **kwargs)
    _fits.append(((time.process_time() - c0) * 1000, (time.perf_counter() - t0) * 1000, fit.nfev))
    return fit


def _line(name: str, v: np.ndarray, unit: str) -> str:
    return (f"  {name}: median {np.median(v):.0f}, p90 {np.percentile(v, 90):.0f}, "
            f"worst {v.max():.0f}{unit}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    find_points(np.zeros((64, 64, 3), np.uint8))  # OpenCV's one-time set-up is no fit's cost
    prismcore.scan.measure.fit_box = _recorded
    per_scene: list[tuple[float, int]] = []
    for seed in range(args.seed, args.seed + args.scenes):
        sc = clutter_scene(seed)
        before = len(_fits)
        found = find_points(sc.image)
        if found.points is not None:
            spec = ScanSpec(image="x", points=found.points, side_face=found.side_face)
            with contextlib.suppress(InputError):  # refused points still cost their fit
                plan_scan(spec, sc.image)
        per_scene.append((sum(f[0] for f in _fits[before:]), seed))
    if not _fits:
        print("no scene gave points to fit")
        return
    cpu, wall, nfev = (np.array([f[k] for f in _fits]) for k in range(3))
    print(f"box fits: {len(_fits)} over {args.scenes} scenes (load average {os.getloadavg()[0]:.1f})")
    print(_line("CPU ms per fit", cpu, ""))
    print(_line("wall ms per fit (shared machine, noisy)", wall, ""))
    print(_line("solver evaluations per fit", nfev, f"; all fits {nfev.sum()}"))
    worst = sorted(per_scene, reverse=True)[:5]
    print("  most fit CPU per scene (ms, seed): " + ", ".join(f"{c:.0f} ({s})" for c, s in worst))


if __name__ == "__main__":
    main()

"""Accuracy sweep over random synthetic scenes: dimension errors against ground truth.

Run: .venv/bin/python benchmarks/accuracy.py [--scenes N] [--seed S]
Prints, per scenario, the median and worst relative error of width, height and depth, for our
default method and for the paper's method on the same clicks, and the coverage of the stated
sigma: the share of measured (not given) dimensions whose error lies within 2 sigma.
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table

from prismcore import ScanSpec, run_scan
from prismcore.report import report_dict
from prismsynth import Box, Style, render_front_view, render_oblique_view, render_side_view


def _clicks(points: dict, names: tuple[str, ...], rng: np.random.Generator, px: float) -> list:
    return [list(np.rint(np.asarray(points[n]) + rng.uniform(-px, px, 2))) for n in names]


def _errors(report: dict, box: Box) -> np.ndarray:
    d = report["dimensions"]
    return np.abs(np.array([d["width"] / box.width_mm, d["height"] / box.height_mm,
                            d["depth"] / box.depth_mm]) - 1)


_NAMES = ("width", "height", "depth")


def _covered(report: dict, box: Box, given: str | None = None) -> np.ndarray:
    """Per measured dimension (the given one left out): its error within 2 stated sigma."""
    d, u = report["dimensions"], report.get("uncertainty") or {}
    true = dict(zip(_NAMES, (box.width_mm, box.height_mm, box.depth_mm), strict=True))
    return np.array([abs(d[n] - true[n]) <= 2 * u.get(n, 0.0) for n in _NAMES if n != given])


def _result(report: dict, box: Box, given: str | None = None) -> dict[str, np.ndarray]:
    return {"errors": _errors(report, box), "covered": _covered(report, box, given)}


def _random_scene(rng: np.random.Generator) -> tuple[Box, Style]:
    box = Box(*rng.uniform([40, 30, 25], [250, 200, 150]))
    style = Style(background_close=bool(rng.random() < 0.3), noise_sigma=float(rng.uniform(0, 5)),
                  jpeg_quality=int(rng.integers(65, 96)), lighting=float(rng.uniform(0, 0.5)),
                  blur_sigma=float(rng.uniform(0.3, 1.2)))
    return box, style


def _misses(label: str, report: dict, errors: np.ndarray, target: float) -> None:
    if errors.max() > target:
        edges = {face: [(e["side"], e["support"], e["rms_px"]) for e in f.get("edges", [])
                        if e["support"] < 0.9] for face, f in report["faces"].items()}
        print(f"miss {label}: errors {np.round(errors * 100, 3)} %, weak edges {edges}, "
              f"warnings {report['warnings']}")


def two_views(rng: np.random.Generator, click_px: float) -> dict[str, np.ndarray]:
    box, style = _random_scene(rng)
    seed = int(rng.integers(1 << 30))
    front = render_front_view(box, style=style, seed=seed)
    side = render_side_view(box, style=style, seed=seed + 1)
    pts = _clicks(front.points, ("p1", "p2", "p3"), rng, click_px)
    pts += _clicks(side.points, ("p4", "p5"), rng, click_px)
    spec = ScanSpec(image="f", side_image="s", points=pts,
                    scale={"kind": "mm_per_px", "front": front.mm_per_px, "side": side.mm_per_px})
    out = {}
    for m in ("default", "paper"):
        report = report_dict(run_scan(spec.model_copy(update={"method": m}), front.image, side.image).report)
        out[m] = _result(report, box)
        if m == "default":
            _misses(f"two views {box} {style} seed {seed}", report, out[m]["errors"], 0.005)
    return out


def oblique(rng: np.random.Generator, click_px: float) -> dict[str, np.ndarray]:
    box, style = _random_scene(rng)
    seed, yaw, pitch = int(rng.integers(1 << 30)), float(rng.uniform(15, 45)), float(rng.uniform(5, 25))
    scene = render_oblique_view(box, style=style, seed=seed, yaw_deg=yaw, pitch_deg=pitch)
    names = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
    pts = _clicks(scene.points, names, rng, click_px)
    spec = ScanSpec(image="x", points=pts, focal_px=scene.focal_px,
                    scale={"kind": "pinhole", "distance_mm": scene.distance_mm})
    out = {}
    for m in ("default", "paper"):
        report = report_dict(run_scan(spec.model_copy(update={"method": m}), scene.image).report)
        out[m] = _result(report, box)
        if m == "default":
            _misses(f"oblique {box} {style} seed {seed} yaw {yaw:.1f} pitch {pitch:.1f}",
                    report, out[m]["errors"], 0.02)
    return out


def five_points(rng: np.random.Generator, click_px: float) -> dict[str, dict[str, np.ndarray]]:
    """One oblique photo, P1-P5 only (P6 and P7 are optional), the width given, no focal length:
    measured with the square-on model, whose errors its sigma must own (issue 37's sample: the
    height 17.6 % high, 8 sigma outside its own ±)."""
    box, style = _random_scene(rng)
    seed, yaw, pitch = int(rng.integers(1 << 30)), float(rng.uniform(15, 45)), float(rng.uniform(5, 25))
    scene = render_oblique_view(box, style=style, seed=seed, yaw_deg=yaw, pitch_deg=pitch)
    pts = _clicks(scene.points, ("p1", "p2", "p3", "p4", "p5"), rng, click_px)
    spec = ScanSpec(image="x", points=pts, scale={"kind": "edge", "edge": "width", "length_mm": box.width_mm})
    return {m: _result(report_dict(run_scan(spec.model_copy(update={"method": m}), scene.image).report), box,
                       "width")
            for m in ("default", "paper")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    table = Table(title=f"Relative dimension error over {args.scenes} random scenes each")
    for col in ("scenario", "method", "median", "worst", "target", "within 2 sigma"):
        table.add_column(col)
    for name, fn, click, target in (("two square views", two_views, 4.0, 0.005),
                                    ("oblique + p6/p7 + focal", oblique, 4.0, 0.02),
                                    ("oblique, five points, width given", five_points, 4.0, None)):
        runs = [fn(rng, click) for _ in range(args.scenes)]
        for method in ("default", "paper"):
            errs = np.stack([r[method]["errors"] for r in runs])
            covered = np.concatenate([r[method]["covered"] for r in runs])
            table.add_row(f"{name}, clicks ±{click:g} px", method, f"{np.median(errs):.3%}",
                          f"{errs.max():.3%}", f"{target:.1%}" if method == "default" and target else "-",
                          f"{covered.mean():.0%} of {covered.size}")
    Console().print(table)


if __name__ == "__main__":
    main()

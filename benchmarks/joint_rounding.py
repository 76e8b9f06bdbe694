"""Where the joint fit's worst render errors come from: the boxes' rounded edges (issue 20).

Run: .venv/bin/python benchmarks/joint_rounding.py [--seeds 18 0 8] [--radii 0 0.5 1.5 2.5]

The seeds are the three worst of `benchmarks/joint_fit.py --cases 20`; each is rendered again
with its edges rounded to each radius (`photo_like_views(seed, 3, edge_radius_mm=r)`, all else as
drawn) and measured by the joint fit from the clicks as drawn (0-3 px off). Per radius it prints
the joint fit's larger error on the two dimensions the known edge does not set, whether the
shading gave the radius, and where the edge detector put each view's lines against the true
sharp edges (`scene.points`): the silhouettes' inset (px, inward) and the folds' offsets (px,
signed along the front face's and the side face's outward normals: + inside the face).

A photo-like pose shows the front, the right side and the top, so four of each view's eight
lines are folds (front top, front right = side left, side top) and four are silhouettes.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np

from prismcore import InputError, ScanSpec
from prismcore.geometry.faces import clicked_quads
from prismcore.multiview.joint import View, fit_views
from prismcore.scan.pipeline import plan_scan
from prismcore.spec import KnownEdge
from prismsynth.views import photo_like_views

SIDES = ("top", "right", "bottom", "left")
FOLDS = {("front", 0), ("front", 1), ("side", 0), ("side", 3)}
POINTS = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def line_offsets(scene, scale: KnownEdge) -> dict[tuple[str, int], float]:
    """Per (face, side) line the edge detector fitted: the mean distance (px) of the true sharp
    corners at its ends from it, + where the line lies inside the face."""
    truth = [list(map(float, scene.scene.points[n])) for n in POINTS]
    spec = ScanSpec(image="view.jpg", points=truth, scale=scale)
    plan = plan_scan(spec, scene.image)
    assert spec.points is not None
    marked = clicked_quads(spec.points, two_photo=False, side_face=plan.side_face)
    out = {}
    for face in ("front", "side"):
        corners = np.asarray(getattr(marked, face), dtype=np.float64)
        inside = corners.mean(axis=0)
        for s, edge in enumerate(plan.edges[face]):
            if not edge.fitted:
                continue
            a, b, c = np.asarray(edge.line, dtype=np.float64) / np.hypot(*edge.line[:2])
            ends = corners[[s, (s + 1) % 4]]
            sign = -np.sign(a * inside[0] + b * inside[1] + c)  # + on the side away from the face
            out[(face, s)] = float(np.mean(sign * (ends @ (a, b) + c)))
    return out


def case(seed: int, radius: float) -> dict:
    scenes = photo_like_views(seed, 3, edge_radius_mm=radius)
    p = scenes[0]
    truth = np.array([p.box.width_mm, p.box.height_mm, p.box.depth_mm])
    scale = KnownEdge(edge=p.known_edge, length_mm=p.known_length_mm)  # type: ignore[arg-type]
    joint = fit_views([View(q.image, q.click_list(), name=f"view {i + 1}") for i, q in enumerate(scenes)],
                      scale)
    d = joint.dimensions
    errors = [100 * (m / t - 1) for m, t, name in zip((d.width, d.height, d.depth), truth,
                                                       ("width", "height", "depth"), strict=True)
              if name != p.known_edge]
    silhouettes, folds = [], []
    for q in scenes:
        try:
            offsets = line_offsets(q, scale)
        except InputError:
            continue
        for key, px in offsets.items():
            (folds if key in FOLDS else silhouettes).append(px)
    return {"worst_pct": max(errors, key=abs), "read": bool(d.notes), "silhouette_px": silhouettes,
            "fold_px": folds}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[18, 0, 8])
    parser.add_argument("--radii", type=float, nargs="+", default=[0.0, 0.5, 1.5, 2.5])
    args = parser.parse_args(argv)
    print(f"{'seed':>5}{'radius mm':>11}{'joint worst %':>15}{'radius read':>13}"
          f"{'silhouette inset px':>22}{'fold offsets px (min..max)':>30}")
    for seed in args.seeds:
        for radius in args.radii:
            c = case(seed, radius)
            sil = statistics.median(c["silhouette_px"]) if c["silhouette_px"] else float("nan")
            folds = c["fold_px"]
            span = f"{min(folds):+.1f}..{max(folds):+.1f}" if folds else "-"
            print(f"{seed:>5}{radius:>11.1f}{c['worst_pct']:>+15.2f}{'yes' if c['read'] else 'no':>13}"
                  f"{sil:>22.1f}{span:>30}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

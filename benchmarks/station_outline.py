"""How far the station's outline lies from the part's true silhouette on renders, side by side.

For each seed's correct station (calibrated with its true camera) and the sample reference part's
placements (`prism sample --station`'s, the camera not nudged): the photo registered and the part
segmented as `measure_on_station` does, then its outline's points, as the threshold found them and
as `refine_outline` places them (the refinement's normals from the TRUE silhouette, so only the
step's reading is measured), each as a signed distance from the true silhouette's nearest side
(px, + outside), split by the side's kind: the foot (a bottom edge on the support), the top (a top
edge) and the vertical edges. Points within a tenth of a side's length of its corners are left out
(the blur rounds corners). Also each placement's measured dimensions against the truth, so an
offset and the bias it makes are read together.

A dimension is read short where its sides' offsets are negative: a tenth of a pixel on each side
of a 0.25 mm/px footprint is 0.05 mm. The photos are JPEGs of quality 85 at 4:2:0 unless
--chroma 444.

    .venv/bin/python benchmarks/station_outline.py --seeds 1-6
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from prismcore import InputError
from prismcore.station.board import default_board
from prismcore.station.boxfit import project
from prismcore.station.calibrate import calibrate_station
from prismcore.station.edges import refine_outline
from prismcore.station.measure import measure_on_station
from prismcore.station.registration import register
from prismcore.station.segment import segment_part
from prismcore.station.undistort import undistorter
from prismsynth.station import station_scene, station_setup

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))
from cli.sample_command import REFERENCE_MM as SAMPLE_REFERENCE_MM
from cli.sample_command import reference_placements
from station_verification import camera_of, seed_list

KINDS = ("foot", "top", "vertical")
REFERENCE_MM = dict(zip(("width", "depth", "height"), SAMPLE_REFERENCE_MM, strict=True))


def true_hull(corners_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The true silhouette's vertices (M, 2) px in order round it and their corner indices (M,)."""
    idx = cv2.convexHull(corners_px.astype(np.float32), returnPoints=False).ravel()
    return corners_px[idx], idx


def offsets_by_kind(points: np.ndarray, hull: np.ndarray, idx: np.ndarray) -> dict[str, np.ndarray]:
    """Each point's signed distance (px, + outside) from its nearest side of `hull`, by side kind."""
    n = len(hull)
    a, b = hull, np.roll(hull, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("pmk,mk->pm", points[:, None] - a[None], ab) / np.einsum("mk,mk->m", ab, ab), 0, 1)
    dist = np.linalg.norm(points[:, None] - (a[None] + t[..., None] * ab[None]), axis=2)
    side = np.argmin(dist, axis=1)
    normal = np.column_stack([ab[:, 1], -ab[:, 0]]) / np.linalg.norm(ab, axis=1, keepdims=True)
    centre = hull.mean(axis=0)
    normal[np.einsum("mk,mk->m", normal, a - centre) < 0] *= -1  # outward
    signed = np.einsum("pk,pk->p", points - a[side], normal[side])
    away = (t[np.arange(len(points)), side] > 0.1) & (t[np.arange(len(points)), side] < 0.9)
    out: dict[str, list[float]] = {k: [] for k in KINDS}
    for k in range(n):
        i, j = idx[k], idx[(k + 1) % n]
        kind = "foot" if i < 4 and j < 4 else "top" if i >= 4 and j >= 4 else "vertical"
        out[kind].extend(signed[(side == k) & away].tolist())
    return {k: np.asarray(v) for k, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--chroma", choices=("420", "444"), default="420")
    args = parser.parse_args()
    found: dict[str, dict[str, list[np.ndarray]]] = {"threshold": {k: [] for k in KINDS},
                                                     "refined": {k: [] for k in KINDS}}
    errors = []
    for seed in seed_list(args.seeds):
        board = default_board()
        setup = station_setup(seed, board=board)
        cam = camera_of(setup)
        plate = station_scene(seed, setup, parts=0, chroma=args.chroma).plate
        station = calibrate_station(board, plate, camera=cam, plate=plate)
        und = undistorter(cam)
        plate_u = und.image(plate)
        for i, box in enumerate(reference_placements(setup), 1):
            try:
                scene = station_scene(1000 * seed + i, setup, box=box, nudge=False, chroma=args.chroma)
            except ValueError:  # out of this camera's view
                continue
            try:
                m = measure_on_station(scene.photo, station)
                photo_u = und.image(scene.photo)
                reg = register(photo_u, plate_u, scene.photo, station.board, cam, station.plane)
                sil = segment_part(photo_u, plate_u, reg.homography)
            except InputError as exc:
                print(f"seed {seed:3d} placement {i}: refused ({str(exc)[:70]})")
                continue
            errors.append([m.dimensions[k] - v for k, v in REFERENCE_MM.items()])
            hull, idx = true_hull(project(scene.box.corners(), setup.K, setup.R, setup.t))
            origin = np.asarray(sil.origin, np.float64)
            refined = refine_outline(sil.contour - origin, hull - origin, sil.difference) + origin
            for name, pts in (("threshold", sil.contour), ("refined", refined)):
                for kind, values in offsets_by_kind(pts, hull, idx).items():
                    found[name][kind].append(values)
    print(f"outline's offset from the true silhouette, px (+ outside), {args.chroma}, seeds {args.seeds}")
    print(f"{'':<10} {'side':<9} {'points':>7} {'mean':>7} {'median':>7} {'p10':>7} {'p90':>7}")
    for name, kinds in found.items():
        for kind, parts in kinds.items():
            v = np.concatenate(parts) if parts else np.zeros(0)
            if len(v):
                p10, p50, p90 = np.percentile(v, [10, 50, 90])
                print(f"{name:<10} {kind:<9} {len(v):7d} {v.mean():+7.3f} {p50:+7.3f} {p10:+7.3f} "
                      f"{p90:+7.3f}")
    e = np.asarray(errors)
    if len(e):
        se = e.std(axis=0, ddof=1) / np.sqrt(len(e)) if len(e) > 1 else np.full(3, np.nan)
        print(f"{len(e)} placements: mean error " + ", ".join(
            f"{k} {e[:, j].mean():+.3f} +- {se[j]:.3f}" for j, k in enumerate(REFERENCE_MM)) + " mm")


if __name__ == "__main__":
    main()

"""Check the hand marks of the real box video against the true box, independently of the engine.

Run: .venv/bin/python benchmarks/real_video_marks.py [marks.json] [--together 164,105]
For each marked frame, fits the 258 x 75 x 189 mm box (pose and focal length free, principal point
at the image centre) to the six distinct points by least squares (OpenCV's projection, SciPy's
solver) and prints each point's residual (px), then the same with height and depth free
(their errors against the truth: what the clicks alone say, whatever the engine does). Marks
that fit the true box within about 1 px RMS are consistent; a point with a large residual is
wrongly marked, or the frame's truth assignment is. Use it to find marks to look at again, never
to move a mark: a re-mark is decided from the picture alone.

--together: ONE box (width known; height, depth and the focal length shared) with a pose per
frame, fitted to the marks of the frames listed, and each frame's RMS px: whether the marks of
those frames can be views of one rigid box by one pinhole camera at all (a tracker's points are).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_video_data import MARKS, load_marks, truth_mm

NAMES = ("P1", "P2", "P3", "P5", "P6", "P7")


def box_points(side: str, w: float, h: float, d: float) -> np.ndarray:
    """World corners of NAMES (X along P1->P2, Y down the front, Z into the box), mm."""
    far = {"right": ((w, 0, d), (w, h, d)), "left": ((0, 0, d), (0, h, d)),
           "top": ((0, 0, d), (w, 0, d))}[side]
    return np.array([(0, 0, 0), (w, 0, 0), (w, h, 0), far[0], (0, h, 0), far[1]], dtype=np.float64)


def fit(image_pts: np.ndarray, side: str, truth: dict[str, float], dims_free: bool, centre=(319.5, 239.5)):
    """Least-squares pose + focal (+ height/depth when `dims_free`); best of several focal starts."""
    def residual(x: np.ndarray) -> np.ndarray:
        h, d = (x[7], x[8]) if dims_free else (truth["height"], truth["depth"])
        K = np.array([[x[6], 0, centre[0]], [0, x[6], centre[1]], [0, 0, 1.0]])
        proj, _ = cv2.projectPoints(box_points(side, truth["width"], h, d), x[:3], x[3:6], K, None)
        return (proj.reshape(-1, 2) - image_pts).ravel()

    best = None
    for f in (400.0, 550.0, 700.0, 900.0, 1200.0):
        K = np.array([[f, 0, centre[0]], [0, f, centre[1]], [0, 0, 1.0]])
        obj = box_points(side, truth["width"], truth["height"], truth["depth"])
        _, r, t = cv2.solvePnP(obj, image_pts, K, None, flags=cv2.SOLVEPNP_SQPNP)
        sol = least_squares(residual, np.r_[r.ravel(), t.ravel(), f, truth["height"], truth["depth"]],
                            x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    return best


def together(frames: list[dict], centre=(319.5, 239.5)) -> tuple[float, float, float, np.ndarray]:
    """One box over `frames` (same side face): focal px, height and depth mm, and each frame's
    residuals (len(frames), 6) px, from each frame's own true-box pose as the start."""
    side = frames[0]["side"]
    if any(f["side"] != side or f["truth"] != frames[0]["truth"] for f in frames):
        raise ValueError("one box over frames that show different faces: give frames of one side and truth")
    width = truth_mm(frames[0])["width"]
    pts = [np.array([f["points"][n] for n in NAMES], dtype=np.float64) for f in frames]
    poses = [fit(p, side, truth_mm(f), False).x[:6] for p, f in zip(pts, frames, strict=True)]

    def residual(x: np.ndarray) -> np.ndarray:
        K = np.array([[x[0], 0, centre[0]], [0, x[0], centre[1]], [0, 0, 1.0]])
        obj = box_points(side, width, x[1], x[2])
        out = []
        for i, p in enumerate(pts):
            proj, _ = cv2.projectPoints(obj, x[3 + 6 * i:6 + 6 * i], x[6 + 6 * i:9 + 6 * i], K, None)
            out.append((proj.reshape(-1, 2) - p).ravel())
        return np.concatenate(out)

    truth = truth_mm(frames[0])
    sol = least_squares(residual, np.r_[650.0, truth["height"], truth["depth"], np.concatenate(poses)],
                        x_scale="jac")
    return float(sol.x[0]), float(sol.x[1]), float(sol.x[2]), np.linalg.norm(sol.fun.reshape(-1, 2), axis=1
                                                                             ).reshape(len(frames), -1)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("marks", nargs="?", type=Path, default=MARKS, help="the marks file")
    parser.add_argument("--together", help="frame indices, comma-separated: ONE box over their marks")
    args = parser.parse_args(argv)
    if args.together:
        by_index = {f["index"]: f for f in load_marks(args.marks)["frames"]}
        try:
            wanted = [int(i) for i in args.together.split(",")]
        except ValueError:
            parser.error(f"--together {args.together!r}: frame indices, e.g. 164,105")
        if unknown := [i for i in wanted if i not in by_index]:
            parser.error(f"--together: no marks for frames {unknown} (marked: {sorted(by_index)})")
        f, h, d, res = together([by_index[i] for i in wanted])
        print(f"one box over frames {wanted}: f {f:.0f} px, {h:.1f} x {d:.1f} mm")
        for i, r in zip(wanted, res, strict=True):
            print(f"{i:4d} RMS {float(np.sqrt(np.mean(r**2))):4.1f} px, "
                  + " ".join(f"{n} {v:4.1f}" for n, v in zip(NAMES, r, strict=True)))
        return 0
    marks = load_marks(args.marks)
    errors: list[tuple[float, float]] = []
    for frame in marks["frames"]:
        pts = np.array([frame["points"][n] for n in NAMES], dtype=np.float64)
        truth = truth_mm(frame)
        fixed, free = fit(pts, frame["side"], truth, False), fit(pts, frame["side"], truth, True)
        res = np.linalg.norm(fixed.fun.reshape(-1, 2), axis=1)
        rms = float(np.sqrt(np.mean(res**2)))
        free_rms = float(np.sqrt(np.mean(np.sum(free.fun.reshape(-1, 2) ** 2, axis=1))))
        h, d = free.x[7], free.x[8]
        errors.append((100 * (h / truth["height"] - 1), 100 * (d / truth["depth"] - 1)))
        print(f"{frame['index']:4d} {frame['side']:5s} true box: f {fixed.x[6]:5.0f} px, RMS {rms:4.1f} px, "
              + " ".join(f"{n} {v:4.1f}" for n, v in zip(NAMES, res, strict=True))
              + f" | height, depth free: f {free.x[6]:5.0f}, {h:5.1f} x {d:5.1f} mm "
              f"({errors[-1][0]:+.1f} %, {errors[-1][1]:+.1f} %), RMS {free_rms:4.1f} px")
    if errors:
        # What the clicks alone say (width known, focal free): a bound on what any engine can do with them.
        med_h = float(np.median([abs(e[0]) for e in errors]))
        med_d = float(np.median([abs(e[1]) for e in errors]))
        over = [f["index"] for f, e in zip(marks["frames"], errors, strict=True) if max(map(abs, e)) > 5]
        print(f"marks alone, height/depth free: median |error| height {med_h:.1f} %, depth {med_d:.1f} %; "
              f"frames over 5 %: {over}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

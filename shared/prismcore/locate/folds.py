"""Zero-click, step 7: two faces whose fold is too faint to split their region, split at it.

Their region's outline, a pentagon or a quad (the bends at the fold's ends too shallow to see),
is cut where the colour change runs its whole length in a direction between the box's two edges
beside it (`_pentagon_box`, `_quad_box`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import cv2
import numpy as np

from prismcore.geometry.faces import quad_area
from prismcore.locate.outlines import _SHRINK_PX, _Box, _clockwise, _Work
from prismcore.locate.second_face import across_samples

__all__: list[str] = []

# A fold guessed inside a silhouette whose outline shows one end of it (a pentagon) or neither
# (a quad): the colour change (`_fold_strength`, Lab units) it must show. A single face's print
# splits a quad as well as a fold would: the PnP screen and the fit refuse a flat "box".
_PENTAGON_FOLD_STRENGTH = 1.2
_QUAD_FOLD_STRENGTH = 2.5
_MIN_SPLIT = 0.08  # of the silhouette's area: the smallest face split off it
_SPLIT_MIN_FRACTION = 0.02  # of the work image's area: the smallest silhouette split


def _split_boxes(work: _Work, shape: tuple[int, ...], hint_work: np.ndarray | None) -> list[_Box]:
    """Two faces each from the large silhouettes of 4 or 5 sides (`_pentagon_box`,
    `_quad_box`), those around the hint only when there is one."""
    h, w = shape[:2]
    grad = work.gradient
    out = []
    for outline, contour, sampling in work.merged:
        if abs(quad_area(outline)) < _SPLIT_MIN_FRACTION * h * w:
            continue
        if hint_work is not None and cv2.pointPolygonTest(
                outline.astype(np.float32), (float(hint_work[0]), float(hint_work[1])), False) < 0:
            continue
        box = (_pentagon_box if len(outline) == 5 else _quad_box)(outline, contour, grad)
        if box is not None:
            for f in box.faces:  # split from what one sampling saw: not known to be stable
                f.seen = sampling
            out.append(box)
    return out


_FOLD_TURN_DEG = 6.0  # a fold's direction lies between its two neighbour sides' within this


def _fold_strength(grad: tuple[np.ndarray, np.ndarray], a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(m,): how surely a fold runs along each segment a[i]-b[i] (a, b: (m, 2)): the colour
    change across it (`locate_faces.across_samples`) that its middle 80 % shows nearly
    everywhere, the 20th percentile of 24 samples. A fold between two faces of nearly one
    shade is faint but runs their whole height; a label's border or a stripe is strong over
    part of it and absent elsewhere."""
    samples, _ = across_samples(grad, a, b, 24)
    return np.asarray(np.percentile(samples, 20, axis=1), dtype=np.float64)


def _fold_between(origins: np.ndarray, left: np.ndarray, right: np.ndarray, p: np.ndarray,
                  q: np.ndarray, grad: tuple[np.ndarray, np.ndarray]
                  ) -> tuple[float, np.ndarray, np.ndarray] | None:
    """The fold from one of `origins` (k, 2) to the side p-q that the colour change shows best
    (`_fold_strength`), among the directions between `left` and `right` (the box's edges
    parallel to the fold in 3D: in the photo its direction lies between theirs): its strength,
    origin and end; None when no such direction meets the side inside its middle 90 %."""
    a, b = _unit(left), _unit(right)
    if a @ b < 0:
        b = -b
    turn = math.atan2(a[0] * b[1] - a[1] * b[0], float(a @ b))  # signed, a to b
    margin = math.copysign(math.radians(_FOLD_TURN_DEG), turn)
    steps = max(7, int(math.degrees(abs(turn)) / 2) + 7)
    angles = math.atan2(a[1], a[0]) + np.linspace(-margin, turn + margin, steps)
    d = np.tile(np.column_stack([np.cos(angles), np.sin(angles)]), (len(origins), 1))
    start = np.repeat(origins, steps, axis=0)
    side = q - p
    det = d[:, 1] * side[0] - d[:, 0] * side[1]  # start + t d = p + s side, by Cramer's rule
    ok = np.abs(det) > 1e-9
    rhs = p - start
    safe = np.where(ok, det, 1.0)
    t = np.where(ok, (rhs[:, 1] * side[0] - rhs[:, 0] * side[1]) / safe, -1.0)
    s = np.where(ok, (d[:, 0] * rhs[:, 1] - d[:, 1] * rhs[:, 0]) / safe, -1.0)
    ok &= (t > 0) & (s > 0.05) & (s < 0.95)
    if not ok.any():
        return None
    ends = p + s[ok, None] * side
    got = _fold_strength(grad, start[ok], ends)
    k = int(np.argmax(got))
    return float(got[k]), start[ok][k], ends[k]


def _unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / max(float(np.linalg.norm(v)), 1e-12), dtype=np.float64)


def _snap_fold(o: np.ndarray, x: np.ndarray, contour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fold o-x run on to where its line leaves the region (`contour`, (n, 2)): a shallow
    bend's vertex, which the outline's polygon misplaces, is where the fold meets the outline."""
    u = _unit(x - o)
    along = (contour - o) @ u
    near = np.abs((contour - o) @ np.array([-u[1], u[0]])) < 2.0
    length = float(np.linalg.norm(x - o))
    first = near & (along < 0.5 * length)
    last = near & (along > 0.5 * length)
    t0 = float(along[first].min()) if first.any() else 0.0
    t1 = float(along[last].max()) if last.any() else length
    # The region lies inside its thickened edges: its outline _SHRINK_PX short of the corner.
    return o + (t0 - _SHRINK_PX) * u, o + (t1 + _SHRINK_PX) * u


def _split_box(outline: np.ndarray, contour: np.ndarray, fold: tuple[np.ndarray, np.ndarray],
               halves: Callable[[np.ndarray, np.ndarray], list[np.ndarray]]) -> _Box | None:
    """The box of the two faces a fold splits a silhouette into (`halves(o, x)` from the fold's
    ends, snapped to the region's outline); None when one is a sliver (a fold found beside a
    side is that side's own edge)."""
    hull = outline.astype(np.float64)
    area = abs(quad_area(hull))
    faces = [_clockwise(h) for h in halves(*_snap_fold(*fold, contour))]
    if min(f.area for f in faces) < _MIN_SPLIT * area:
        return None
    return _Box(faces, area, hull.mean(axis=0), hull)


_FOLD_SLIDE = np.linspace(0.0, 0.3, 5)[1:]  # of a side: a shallow bend's vertex is vague


def _pentagon_box(pentagon: np.ndarray, contour: np.ndarray, grad: tuple[np.ndarray, np.ndarray]
                  ) -> _Box | None:
    """The two faces whose silhouette is `pentagon`: a hexagon whose bend at one end of the
    fold is too shallow to see. The fold runs from near a vertex (a shallow bend's vertex lies
    anywhere along it: the fold starts on either side beside it) to the opposite side, between
    the directions of the two sides beside that one (the box's edges parallel to the fold)."""
    v = pentagon
    best: tuple[float, np.ndarray, np.ndarray, int] | None = None
    for i in range(5):
        a, b, c, d, e = (v[(i + k) % 5] for k in range(5))  # fold from near a to the side c-d
        origins = np.concatenate([a[None], a + _FOLD_SLIDE[:, None] * (b - a),
                                  a + _FOLD_SLIDE[:, None] * (e - a)])
        got = _fold_between(origins, c - b, d - e, c, d, grad)
        if got is not None and (best is None or got[0] > best[0]):
            best = (*got, i)
    if best is None or best[0] < _PENTAGON_FOLD_STRENGTH:
        return None
    _, b, c, d, e = (v[(best[3] + k) % 5] for k in range(5))
    return _split_box(v, contour, (best[1], best[2]),
                      lambda o, x: [np.array([o, b, c, x]), np.array([x, d, e, o])])


def _quad_box(quad: np.ndarray, contour: np.ndarray, grad: tuple[np.ndarray, np.ndarray]
              ) -> _Box | None:
    """The two faces whose silhouette is `quad` (both bends at the fold's ends too shallow):
    a fold from one side to the opposite one, between the directions of the other two."""
    v = quad
    best: tuple[float, np.ndarray, np.ndarray, int] | None = None
    for i in range(2):
        a, b, c, d = (v[(i + k) % 4] for k in range(4))  # fold from side a-b to side c-d
        origins = a + np.linspace(0.1, 0.9, 11)[:, None] * (b - a)
        got = _fold_between(origins, c - b, d - a, c, d, grad)
        if got is not None and (best is None or got[0] > best[0]):
            best = (*got, i)
    if best is None or best[0] < _QUAD_FOLD_STRENGTH:
        return None
    a, b, c, d = (v[(best[3] + k) % 4] for k in range(4))
    return _split_box(v, contour, (best[1], best[2]),
                      lambda o, x: [np.array([o, b, c, x]), np.array([x, d, a, o])])

"""Zero-click, step 3: faces that share an edge (two corners each) as boxes, scored, and a box's
faces named: the top face is the one above the others, the front the larger of the upright ones,
the other the side (right or left), else the top; then P1..P7 on its corners.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from prismcore.geometry.faces import SideFace
from prismcore.locate.outlines import _Box, _line, _Quad

__all__: list[str] = []

def _shared(a: _Quad, b: _Quad) -> tuple[tuple[int, int], tuple[int, int]] | None:
    """The edge a and b share: (i, i+1) of a matched to b's corners, or None."""
    tol = 0.12 * math.sqrt(min(a.area, b.area)) + 3.0
    d = np.linalg.norm(a.corners[:, None] - b.corners[None], axis=2)
    for i in range(4):
        j = (i + 1) % 4
        ki, kj = int(np.argmin(d[i])), int(np.argmin(d[j]))
        if d[i, ki] < tol and d[j, kj] < tol and ki != kj and (ki - kj) % 4 in (1, 3):
            # Two faces lie on either side of their fold; the same face found twice (at two
            # edge sensitivities) lies on one side and is no pair.
            fold = _line(a.corners[i], a.corners[j])
            sa, sb = (fold[:2] @ q.corners.mean(axis=0) + fold[2] for q in (a, b))
            if sa * sb < 0:
                return (i, j), (ki, kj)
    return None


def _boxes(quads: list[_Quad]) -> list[_Box]:
    n = len(quads)
    pairs = {(i, j) for i in range(n) for j in range(i + 1, n) if _shared(quads[i], quads[j])}
    boxes: list[list[int]] = []
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                if {(i, j), (i, k), (j, k)} <= pairs:
                    boxes.append([i, j, k])
    # Every pair too, those of a triple included: a false third face (a label, a shadow) must
    # not hide the two faces that do make a box; the PnP screen sorts them out.
    boxes += [[i, j] for i, j in sorted(pairs)]
    out = []
    for members in boxes:
        faces = [quads[m] for m in members]
        allc = np.concatenate([f.corners for f in faces]).astype(np.float32)
        hull = cv2.convexHull(allc).reshape(-1, 2).astype(np.float64)
        out.append(_Box(faces, float(cv2.contourArea(hull.astype(np.float32))), hull.mean(axis=0), hull))
    return out


def _score(box: _Box, shape: tuple[int, int]) -> float:
    h, w = shape
    off = np.linalg.norm(box.centre - np.array([w / 2, h / 2])) / math.hypot(w / 2, h / 2)
    return float(box.area * (1.0 - 0.6 * off) * (1.1 if len(box.faces) == 3 else 1.0))


def _from(quad: np.ndarray, start: int) -> np.ndarray:
    """The quad's corners clockwise, starting at corner `start`."""
    return np.roll(quad, -start, axis=0)


def _label(box: _Box) -> tuple[dict[str, np.ndarray], SideFace] | None:
    """P1..P7 (work px) and the second face of a box's faces, per `prismcore.geometry.faces`; None when
    the faces labelled front and side share no edge (three faces read the wrong way round)."""
    faces = sorted(box.faces, key=lambda f: f.corners[:, 1].mean())
    if len(faces) == 3:
        upright = faces[1:]  # the highest face is the top
        top = None
    else:
        a, b = faces
        fold = _shared(a, b)
        if fold is None:
            return None
        (ia, ja), _ = fold
        d = a.corners[ja] - a.corners[ia]
        top, upright = (a, [b]) if abs(d[0]) > abs(d[1]) else (None, [a, b])
    if top is not None:
        front = upright[0]
        fold = _shared(front, top)
        if fold is None:
            return None
        (i, j), (ki, kj) = fold
        left, _ = (i, j) if front.corners[i, 0] < front.corners[j, 0] else (j, i)
        f = _from(front.corners, left)  # P1, P2, P3, P6
        t_left = ki if left == i else kj
        t_right = kj if left == i else ki
        t = top.corners
        # Clockwise on screen from the top face's lower-right: BR, BL, TL, TR.
        order = _from(t, t_right)
        p1, p2 = (f[0] + t[t_left]) / 2, (f[1] + t[t_right]) / 2
        return {"p1": p1, "p2": p2, "p3": f[2], "p6": f[3], "p4": p1, "p5": order[2],
                "p7": order[3]}, "top"
    front, second = sorted(upright, key=lambda f: -f.area)
    fold = _shared(front, second)
    if fold is None:
        return None
    (i, j), (ki, kj) = fold
    upper, _ = (i, j) if front.corners[i, 1] < front.corners[j, 1] else (j, i)
    s_upper = ki if upper == i else kj
    s_lower = kj if upper == i else ki
    s = second.corners
    if s[:, 0].mean() > front.corners[:, 0].mean():
        f = _from(front.corners, (upper - 1) % 4)  # TL, TR (upper), BR (lower), BL
        side = _from(s, s_upper)  # TL (shared upper), TR, BR, BL (shared lower)
        p2, p3 = (f[1] + s[s_upper]) / 2, (f[2] + s[s_lower]) / 2
        return {"p1": f[0], "p2": p2, "p3": p3, "p6": f[3], "p4": p2, "p5": side[1],
                "p7": side[2]}, "right"
    f = _from(front.corners, upper)  # TL (upper), TR, BR, BL (lower)
    side = _from(s, (s_upper - 1) % 4)  # TL, TR (shared upper), BR (shared lower), BL
    p1, p6 = (f[0] + s[s_upper]) / 2, (f[3] + s[s_lower]) / 2
    return {"p1": p1, "p2": f[1], "p3": f[2], "p6": p6, "p4": p1, "p5": side[0],
            "p7": side[3]}, "left"

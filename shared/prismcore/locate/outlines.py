"""Zero-click, step 1-2: the faces a photo's colour edges enclose, on the work image.

Colour edges (Canny on each Lab channel, at two sensitivities, with long straight line
segments drawn in where Canny misses a faint fold), thickened so a face's outline closes; the
regions whose outline is a convex quadrilateral are face candidates, pooled over two samplings
of the photo (`_all_faces`: each keeps which samplings found it). A six-sided silhouette is two
faces around a fold (`_hexagon_box`); silhouettes of four or five sides are kept for
`locate.folds`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np

from prismcore.geometry.faces import quad_area

__all__: list[str] = []

_EDGE_DILATE = 3  # px (work scale): closes small gaps in a face's outline
_SHRINK_PX = 1.5  # px (work scale): how far inside its edges a region's outline lies
_MIN_FACE_FRACTION = 0.002  # of the work image's area
_SOLIDITY = 0.88
_SILHOUETTE_SOLIDITY = 0.8  # a box's silhouette (faces merged) may be notched more
_FOLD_SUPPORT = 0.6  # a silhouette's folds must lie on edges this much
_FINE_EPS = (0.02, 0.012)  # of the outline's length: tolerances that see a faint fold's bends
_SAMPLINGS = 0b11  # the work image (bit 1) and the same half a work px along (bit 2)
_RESAMPLE_PX = 0.5  # work px


@dataclass
class _Quad:
    corners: np.ndarray  # (4, 2) clockwise on screen, work px
    area: float
    seen: int = _SAMPLINGS  # which samplings of the photo found it (found faces; others: all)


@dataclass
class _Box:
    faces: list[_Quad]
    area: float
    centre: np.ndarray
    hull: np.ndarray


_LEVELS = ((20.0, 50.0), (8.0, 20.0))  # Canny thresholds on L (a, b: 0.4 of them)


def _edges(lab: np.ndarray, low: float, high: float) -> np.ndarray:
    """(h, w) uint8 edge map (255 on edges) from all three channels of a blurred Lab image."""
    edges = np.asarray(cv2.Canny(lab[..., 0], low, high, L2gradient=True), dtype=np.uint8)
    for c in (1, 2):
        edges = edges | np.asarray(cv2.Canny(lab[..., c], 0.4 * low, 0.4 * high, L2gradient=True),
                                   dtype=np.uint8)
    return np.asarray(cv2.dilate(edges, np.ones((_EDGE_DILATE, _EDGE_DILATE), np.uint8)), dtype=np.uint8)


_LSD = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)
_LONG_PX = 30.0  # work px: a fold this long and straight is drawn even where Canny misses it
_EXTEND_PX = 8.0  # work px added at both ends of such a segment


def _segments(gray: np.ndarray) -> np.ndarray:
    """(n, 4) float64: LSD's line segments (x0, y0, x1, y1), work px."""
    lines = _LSD.detect(gray)[0]
    return np.zeros((0, 4)) if lines is None else lines.reshape(-1, 4).astype(np.float64)


def _long_lines(segments: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """(h, w) uint8: the long straight segments, thickened (a faint fold between two faces of
    nearly the same shade is long and straight; texture and print are short)."""
    out = np.zeros(shape[:2], np.uint8)
    seg = segments
    long = seg[np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) >= _LONG_PX]
    for x0, y0, x1, y1 in long:
        # Lengthened: a fold's ends fade where it meets the outline; bridging that gap is what
        # separates the two faces' regions.
        d = np.array([x1 - x0, y1 - y0]) / math.hypot(x1 - x0, y1 - y0) * _EXTEND_PX
        a, b = np.array([x0, y0]) - d, np.array([x1, y1]) + d
        cv2.line(out, (round(a[0]), round(a[1])), (round(b[0]), round(b[1])), 255, _EDGE_DILATE)
    return out


@dataclass
class _Work:
    """What the search saw on the work image, kept for proposing faces from one face."""

    lab: np.ndarray  # (h, w, 3) uint8, blurred
    segments: np.ndarray  # (n, 4) LSD segments, work px
    # Silhouettes (4 or 5 sides) two faces may have merged into, with their regions' outlines
    # ((n, 2) work px): split only when nothing else is found (`_split_boxes`); and the sampling
    # that saw each.
    merged: list[tuple[np.ndarray, np.ndarray, int]] = field(default_factory=list)

    @functools.cached_property
    def gradient(self) -> tuple[np.ndarray, np.ndarray]:
        """x and y derivatives of `lab`, each (h, w, 3) float32 (Lab units per px): made once,
        for whichever proposals need it."""
        f = self.lab.astype(np.float32)
        return (np.asarray(cv2.Sobel(f, cv2.CV_32F, 1, 0), dtype=np.float32) / 8,
                np.asarray(cv2.Sobel(f, cv2.CV_32F, 0, 1), dtype=np.float32) / 8)

    @functools.cached_property
    def strength(self) -> np.ndarray:
        """`_strength` of `lab`, made once (the first sampling's faces and the pooling of both
        samplings read it alike)."""
        return _strength(self.lab)


def _all_faces(small: np.ndarray) -> tuple[list[_Quad], list[_Box], _Work]:
    """Face quads and silhouettes pooled over two samplings of the photo: the work image and the
    same resampled half a work px along. Whether a face's region closes or leaks into its
    surroundings can turn on one grey level; found in either sampling a face is kept, with the
    samplings that found it (`_Quad.seen`), so a box resting on a face only one of them found
    says that a slight change of the photo may lose it (`_measure`)."""
    quads, silhouettes, work = _faces_once(small, 0b01)
    move = np.array([[1, 0, _RESAMPLE_PX], [0, 1, _RESAMPLE_PX]], dtype=np.float32)
    resampled = cv2.warpAffine(small, move, (small.shape[1], small.shape[0]), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_REPLICATE)
    quads2, silhouettes2, work2 = _faces_once(resampled, 0b10)
    for q in quads2:
        _keep_sharper(quads, _Quad(q.corners - _RESAMPLE_PX, q.area, q.seen), lambda: work.strength)
    for box in silhouettes2:
        moved = _Box([_Quad(f.corners - _RESAMPLE_PX, f.area, f.seen) for f in box.faces], box.area,
                     box.centre - _RESAMPLE_PX, box.hull - _RESAMPLE_PX)
        twin = next((b for b in silhouettes if len(b.faces) == len(moved.faces) and all(
            _same_face(f, g) for f, g in zip(b.faces, moved.faces, strict=True))), None)
        if twin is None:
            silhouettes.append(moved)
        else:
            for f in twin.faces:
                f.seen |= 0b10
    work.merged += [(o - _RESAMPLE_PX, c - _RESAMPLE_PX, seen) for o, c, seen in work2.merged]
    return quads, silhouettes, work


def _faces_once(small: np.ndarray, sampling: int) -> tuple[list[_Quad], list[_Box], _Work]:
    """Face quads at each edge sensitivity (a faint fold needs the lower one, a textured face
    the higher), the same face found twice kept once; each tagged with `sampling`."""
    lab = cv2.cvtColor(cv2.GaussianBlur(small, (0, 0), 1.0), cv2.COLOR_RGB2Lab)
    quads: list[_Quad] = []
    maps = [_edges(lab, low, high) for low, high in _LEVELS]
    segments = _segments(lab[..., 0])
    maps.append(maps[0] | _long_lines(segments, lab.shape))
    folds = cv2.dilate(np.maximum.reduce(maps), np.ones((3, 3), np.uint8))
    silhouettes: list[_Box] = []
    work = _Work(lab, segments)
    for edges in maps:
        found, outlines = _faces(edges)
        for outline, contour in outlines:
            if len(outline) != 6:
                work.merged.append((outline, contour.reshape(-1, 2).astype(np.float64), sampling))
                continue
            box = _hexagon_box(outline, folds)
            if box is not None:
                for f in box.faces:
                    f.seen = sampling
                silhouettes.append(box)
        for q in found:
            q.seen = sampling
            _keep_sharper(quads, q, lambda: work.strength)  # made only when a face is found twice
    return quads, silhouettes, work


def _strength(lab: np.ndarray) -> np.ndarray:
    """(h, w) float32: colour gradient magnitude (sum over the Lab channels)."""
    gx = np.abs(cv2.Sobel(lab, cv2.CV_16S, 1, 0)).astype(np.float32)
    gy = np.abs(cv2.Sobel(lab, cv2.CV_16S, 0, 1)).astype(np.float32)
    per_channel = np.sqrt(gx * gx + gy * gy)
    # The channels' sum written out: numpy's reduction over the short last axis took 4x longer.
    return np.asarray(per_channel[..., 0] + per_channel[..., 1] + per_channel[..., 2], dtype=np.float32)


def _sharpness(strength: np.ndarray, corners: np.ndarray) -> float:
    """Mean gradient on a quad's sides (their middle 80 %): how well it follows real edges."""
    h, w = strength.shape
    total = 0.0
    for i in range(4):
        p, q = corners[i], corners[(i + 1) % 4]
        xy = np.rint(p + _SIDE_T * (q - p)).astype(int)
        x = np.minimum(np.maximum(xy[:, 0], 0), w - 1)  # np.clip's overhead was most of the cost
        y = np.minimum(np.maximum(xy[:, 1], 0), h - 1)
        total += float(strength[y, x].mean())
    return total / 4


_SIDE_T = np.linspace(0.1, 0.9, 24)[:, None]  # where `_sharpness` samples a side (its middle 80 %)


def _same_face(p: _Quad, q: _Quad) -> bool:
    """One face found twice (at two edge sensitivities or samplings): corners a few px apart."""
    tol = 0.08 * math.sqrt(q.area) + 2.0
    d = p.corners[:, None] - q.corners[None]
    nearest = (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]).min(axis=1).max()
    return bool(np.sqrt(nearest) < tol)


def _keep_sharper(quads: list[_Quad], q: _Quad, strength: Callable[[], np.ndarray]) -> None:
    """Add q unless it is a face already found; of the two, the one whose sides lie on sharper
    edges stays, found by the samplings either was."""
    for k, p in enumerate(quads):
        if _same_face(p, q):
            seen = p.seen | q.seen
            if _sharpness(strength(), q.corners) > _sharpness(strength(), p.corners):
                quads[k] = q
            quads[k].seen = seen
            return
    quads.append(q)


def _line(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    nx, ny = float(q[1] - p[1]), float(p[0] - q[0])
    norm = math.sqrt(nx * nx + ny * ny)  # as np.linalg.norm has it
    nx, ny = nx / norm, ny / norm
    return np.array([nx, ny, -(nx * float(p[0]) + ny * float(p[1]))])


def _meet(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Where two lines (a, b, c) meet: their cross product, written out (np.cross's generality
    was a tenth of the search)."""
    a0, a1, a2 = (float(v) for v in a)
    b0, b1, b2 = (float(v) for v in b)
    w = a0 * b1 - a1 * b0
    if abs(w) < 1e-9:
        return None
    return np.array([(a1 * b2 - a2 * b1) / w, (a2 * b0 - a0 * b2) / w], dtype=np.float64)


def _polygon_of(contour: np.ndarray, sides: int = 4, eps: float = 0.03) -> np.ndarray | None:
    """(sides, 2) corners, clockwise on screen, of a region's outline when it is a convex
    polygon of that many sides (a face: 4; a box's silhouette: 6), else None.

    The approximate corners split the outline into sides; each side's line is fitted to the
    outline points of its middle 80 % and moved out by _SHRINK_PX.
    """
    hull = cv2.convexHull(contour)
    peri = cv2.arcLength(hull, True)
    approx = cv2.approxPolyDP(hull, eps * peri, True).reshape(-1, 2).astype(np.float64)
    if len(approx) != sides:
        return None
    if quad_area(approx) < 0:
        approx = approx[::-1]
    pts = contour.reshape(-1, 2).astype(np.float64)
    pts32 = pts.astype(np.float32)
    centre = approx.mean(axis=0)
    # Every side at once: where each outline point lies along it and off it.
    d = np.concatenate((approx[1:], approx[:1])) - approx
    lengths = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    if lengths.min() < 6:
        return None
    u = d / lengths[:, None]
    rel_x = pts[None, :, 0] - approx[:, 0, None]  # (sides, N)
    rel_y = pts[None, :, 1] - approx[:, 1, None]
    along = rel_x * u[:, 0, None] + rel_y * u[:, 1, None]
    off = rel_y * u[:, 0, None] - rel_x * u[:, 1, None]
    near = ((along > 0.1 * lengths[:, None]) & (along < 0.9 * lengths[:, None])
            & (np.abs(off) < 0.03 * peri + 2))
    if near.sum(axis=1).min() < 5:
        return None
    lines = []
    for i in range(sides):
        vx, vy, x0, y0 = cv2.fitLine(pts32[near[i]], cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
        line = _line(np.array([x0, y0]), np.array([x0 + vx, y0 + vy]))
        if line[:2] @ centre + line[2] < 0:
            line = -line
        line[2] += _SHRINK_PX  # the region lies inside its thickened edges: move the side out
        lines.append(line)
    corners = []
    for i in range(sides):
        x = _meet(lines[(i - 1) % sides], lines[i])
        if x is None or np.linalg.norm(x - approx[i]) > 0.1 * peri:
            return None
        corners.append(x)
    quad = np.array(corners)
    return quad if quad_area(quad) > 0 else None


def _faces(edges: np.ndarray) -> tuple[list[_Quad], list[tuple[np.ndarray, np.ndarray]]]:
    """The face quads among the regions the edges enclose, and the silhouettes a box's faces
    may have merged into where a fold is too faint: hexagons, pentagons (a hexagon whose bend
    at one end of the fold is too shallow to see) and the quads themselves (both bends), each
    with its region's outline ((n, 2) work px)."""
    h, w = edges.shape
    n, labels, stats, _ = cv2.connectedComponentsWithStats((edges == 0).astype(np.uint8), connectivity=4)
    min_area = _MIN_FACE_FRACTION * h * w
    quads: list[_Quad] = []
    outlines: list[tuple[np.ndarray, np.ndarray]] = []
    for i in range(1, n):
        x, y, bw, bh, area = stats[i]
        if area < min_area or area > 0.6 * h * w:
            continue
        if x == 0 or y == 0 or x + bw == w or y + bh == h:
            continue  # cut by the picture's border: not a whole face
        mask = (labels[y:y + bh, x:x + bw] == i).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        contour = max(contours, key=cv2.contourArea) + np.array([x, y])
        outer = cv2.contourArea(contour)
        hull_area = cv2.contourArea(cv2.convexHull(contour))
        solidity = outer / hull_area if hull_area > 0 else 0.0
        if solidity < _SILHOUETTE_SOLIDITY:
            continue
        # A silhouette's outline is notched where a label or a fold's thick edge meets it.
        quad = _polygon_of(contour, 4) if solidity >= _SOLIDITY else None
        if quad is not None:
            quads.append(_Quad(quad, quad_area(quad)))
            # Two faces whose fold is too faint to split their region, their outline's bends
            # at the fold's ends shallow: a quad at the coarse tolerance, a hexagon at a fine one
            # (or no bend to see at all: the quad is their silhouette).
            for eps in _FINE_EPS:
                hexagon = _polygon_of(contour, 6, eps)
                if hexagon is not None:
                    outlines.append((hexagon, contour))
                    break
            else:
                outlines.append((quad, contour))
            continue
        for sides in (6, 5):
            polygon = _polygon_of(contour, sides)
            if polygon is not None:
                outlines.append((polygon, contour))
                break
    return quads, outlines


def _support(edges: np.ndarray, p: np.ndarray, q: np.ndarray) -> float:
    """Fraction of the segment p-q (its middle 80 %) lying on edge pixels."""
    t = np.linspace(0.1, 0.9, 24)[:, None]
    xy = np.rint(p + t * (q - p)).astype(int)
    h, w = edges.shape
    inside = (xy[:, 0] >= 0) & (xy[:, 0] < w) & (xy[:, 1] >= 0) & (xy[:, 1] < h)
    if not inside.all():
        return 0.0
    return float(np.mean(edges[xy[:, 1], xy[:, 0]] > 0))


def _supports(edges: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(n,): `_support` of each segment p[i]-q[i] (p, q: (n, 2))."""
    t = np.linspace(0.1, 0.9, 24)[None, :, None]
    xy = np.rint(p[:, None] + t * (q - p)[:, None]).astype(int)
    h, w = edges.shape
    inside = ((xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)).all(axis=1)
    xy[..., 0] = np.clip(xy[..., 0], 0, w - 1)
    xy[..., 1] = np.clip(xy[..., 1], 0, h - 1)
    return np.where(inside, (edges[xy[..., 1], xy[..., 0]] > 0).mean(axis=1), 0.0)


def _clockwise(corners: np.ndarray) -> _Quad:
    quad = corners if quad_area(corners) > 0 else corners[::-1]
    return _Quad(np.ascontiguousarray(quad), abs(quad_area(quad)))


def _hexagon_box(hexagon: np.ndarray, edges: np.ndarray) -> _Box | None:
    """The box whose silhouette is `hexagon`: three faces around an inner corner (the corner
    completing the parallelograms of alternate vertices), or two faces split by a diagonal;
    whichever folds the edge map shows best."""
    v = hexagon
    best: tuple[float, list[_Quad]] | None = None
    for start in (0, 1):  # three faces: the folds run from the inner corner to v[start::2]
        ends = [start, start + 2, start + 4]
        guess = np.mean([v[k % 6] + v[(k + 2) % 6] - v[(k + 1) % 6] for k in ends], axis=0)
        # Perspective moves the inner corner off the parallelograms' guess: search around it
        # for the point whose three folds lie on edges best.
        reach = 0.08 * math.sqrt(abs(quad_area(v))) + 4.0
        steps = np.linspace(-reach, reach, 9)
        dx, dy = np.meshgrid(steps, steps, indexing="ij")
        centres = guess + np.column_stack([dx.ravel(), dy.ravel()])
        got = np.min([_supports(edges, centres, np.broadcast_to(v[k % 6], centres.shape))
                      for k in ends], axis=0)
        best_at = int(np.argmax(got))
        score, inner = float(got[best_at]), centres[best_at]
        faces = [_clockwise(np.array([inner, v[k % 6], v[(k + 1) % 6], v[(k + 2) % 6]])) for k in ends]
        if best is None or score > best[0]:
            best = (score, faces)
    for i in range(3):  # two faces: a fold from v[i] to v[i + 3]
        score = _support(edges, v[i], v[i + 3])
        faces = [_clockwise(v[[i, i + 1, i + 2, i + 3]]),
                 _clockwise(v[[(i + 3) % 6, (i + 4) % 6, (i + 5) % 6, i]])]
        if best is None or score > best[0]:
            best = (score, faces)
    if best is None or best[0] < _FOLD_SUPPORT:
        return None
    hull = hexagon.astype(np.float64)
    return _Box(best[1], abs(quad_area(hull)), hull.mean(axis=0), hull)

"""Zero-click: find a box in a photo, its visible faces and its reference points P1..P7.

The search, on a copy of the photo about 640 px wide (inside the region of interest, if given):

1. Colour edges (Canny on each Lab channel), thickened so a face's outline closes.
2. The regions the edges enclose; those whose outline is a convex quadrilateral are face
   candidates (a printed label is a hole in its face, not a face of its own).
3. Faces that share an edge (two corners each) form a box: two faces, or three around one
   corner. The top face is the one above the others; the front the larger of the upright
   ones, the other the side (right or left), else the top.
4. The box around the hint, or the largest near the image centre; a second candidate nearly as
   large is an ambiguity the caller must settle with a hint.
5. Full resolution: the engine's own plan (sub-pixel edge fits and the free-focal box fit,
   `pipeline.plan_scan`) places the corners; run twice, the second from the first's corners,
   so that its click residuals measure how well a box explains the edges.
6. When no box passes: the largest faces' neighbours are proposed from the line segments and
   the colour change along them (`locate_faces`), and those boxes go through 4 and 5 alike.
7. When still none passes: two faces whose fold is too faint to split their region are split
   at it; their region's outline, a pentagon or a quad (the bends at the fold's ends too
   shallow to see), is cut where the colour change runs its whole length in a direction
   between the box's two edges beside it (`_pentagon_box`, `_quad_box`).

The confidence combines the edge fits' support, the box fit's residuals and how far the
corners moved from the regions' outlines; below `CONFIDENCE_MIN` the result carries the reason
and no caller should measure it.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from prismcore.errors import InputError
from prismcore.geometry.edges import intersect
from prismcore.geometry.faces import SideFace, quad_area
from prismcore.locate.second_face import across_samples, propose_neighbours
from prismcore.spec import ReferencePoints, ScanSpec, search_area_problem

__all__ = ["CONFIDENCE_MIN", "CONFIDENCE_WARN", "Found", "find_points", "resolve_points"]

CONFIDENCE_MIN = 0.6
CONFIDENCE_WARN = 0.8  # accepted below this: with a warning to check the points
WORK_WIDTH = 640  # px: the search runs on a copy this wide
_EDGE_DILATE = 3  # px (work scale): closes small gaps in a face's outline
_SHRINK_PX = 1.5  # px (work scale): how far inside its edges a region's outline lies
_MIN_FACE_FRACTION = 0.002  # of the work image's area
_SOLIDITY = 0.88
_SILHOUETTE_SOLIDITY = 0.8  # a box's silhouette (faces merged) may be notched more
_AMBIGUOUS = 0.6  # a runner-up this large (relative) is a second box
_FOLD_SUPPORT = 0.6  # a silhouette's folds must lie on edges this much
# A fold guessed inside a silhouette whose outline shows one end of it (a pentagon) or neither
# (a quad): the colour change (`_fold_strength`, Lab units) it must show. A single face's print
# splits a quad as well as a fold would: the PnP screen and the fit refuse a flat "box".
_PENTAGON_FOLD_STRENGTH = 1.2
_QUAD_FOLD_STRENGTH = 2.5
_MIN_SPLIT = 0.08  # of the silhouette's area: the smallest face split off it
_SPLIT_MIN_FRACTION = 0.02  # of the work image's area: the smallest silhouette split
_FINE_EPS = (0.02, 0.012)  # of the outline's length: tolerances that see a faint fold's bends
_PER_CLUSTER = 3  # boxes over one place (other faces or neighbours) measured before the next
_ATTEMPTS = 3  # candidates given the full fit before giving up


@dataclass(frozen=True)
class Found:
    """What the search found.

    Attributes
    ----------
    points : ReferencePoints or None
        P1..P7, image (x, y) px (all seven), or None when nothing box-like was found.
    side_face : {"right", "left", "top"} or None
        The second face P4, P5, P7 mark.
    confidence : float
        0-1; `CONFIDENCE_MIN` and above: the points may be measured.
    reason : str or None
        Why the result must not be measured (a person can act on it); None when accepted.
    faces : tuple of ndarray
        The face quads found, each (4, 2) float64 image px (for overlays).
    candidates : int
        How many box candidates the search saw.
    fit_rms_px : float or None
        RMS distance (px) between the corners of the two fitting passes (see the module).
    timings_ms : dict
        Stage -> milliseconds.
    warnings : tuple of str
        An accepted result below `CONFIDENCE_WARN` says to check the points, as does one that
        is not `stable`.
    stable : bool
        False when the decision sits on a knife edge: the box rests on a face only one of the
        search's two samplings of the photo found, so a slight change of the photo (a grey
        level, a re-encode, a sub-pixel shift: another machine's decoder) may lose it.
    """

    points: ReferencePoints | None
    side_face: SideFace | None
    confidence: float
    reason: str | None
    faces: tuple[np.ndarray, ...] = ()
    candidates: int = 0
    fit_rms_px: float | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    stable: bool = True

    @property
    def ok(self) -> bool:
        return self.reason is None

    def report(self) -> dict[str, Any]:
        """The JSON-ready summary report.json keeps."""
        return {"points_source": "auto", "confidence": round(self.confidence, 3),
                "side_face": self.side_face, "reason": self.reason,
                "points": None if self.points is None else
                {k: [round(v[0], 2), round(v[1], 2)] for k, v in self.points.as_dict().items()},
                "candidates": self.candidates, "warnings": list(self.warnings), "stable": self.stable,
                "fit_rms_px": None if self.fit_rms_px is None else round(self.fit_rms_px, 3)}


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


# --------------------------------------------------------------------------- faces


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
    strength = functools.cache(lambda: _strength(work.lab))
    for q in quads2:
        _keep_sharper(quads, _Quad(q.corners - _RESAMPLE_PX, q.area, q.seen), strength)
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
    # Needed only when a face is found twice.
    strength = functools.cache(lambda: _strength(lab))
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
            _keep_sharper(quads, q, strength)
    return quads, silhouettes, work


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


def _strength(lab: np.ndarray) -> np.ndarray:
    """(h, w) float32: colour gradient magnitude (sum over the Lab channels)."""
    gx = np.abs(cv2.Sobel(lab, cv2.CV_16S, 1, 0)).astype(np.float32)
    gy = np.abs(cv2.Sobel(lab, cv2.CV_16S, 0, 1)).astype(np.float32)
    return np.asarray(np.sqrt(gx * gx + gy * gy).sum(axis=2), dtype=np.float32)


def _sharpness(strength: np.ndarray, corners: np.ndarray) -> float:
    """Mean gradient on a quad's sides (their middle 80 %): how well it follows real edges."""
    t = np.linspace(0.1, 0.9, 24)[:, None]
    h, w = strength.shape
    total = 0.0
    for i in range(4):
        p, q = corners[i], corners[(i + 1) % 4]
        xy = np.rint(p + t * (q - p)).astype(int)
        xy[:, 0] = np.clip(xy[:, 0], 0, w - 1)
        xy[:, 1] = np.clip(xy[:, 1], 0, h - 1)
        total += float(strength[xy[:, 1], xy[:, 0]].mean())
    return total / 4


def _same_face(p: _Quad, q: _Quad) -> bool:
    """One face found twice (at two edge sensitivities or samplings): corners a few px apart."""
    tol = 0.08 * math.sqrt(q.area) + 2.0
    return bool(np.linalg.norm(p.corners[:, None] - q.corners[None], axis=2).min(axis=1).max() < tol)


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
    n = np.array([q[1] - p[1], p[0] - q[0]])
    n /= np.linalg.norm(n)
    return np.array([n[0], n[1], -n @ p])


def _meet(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    x = np.cross(a, b)
    if abs(x[2]) < 1e-9:
        return None
    return np.asarray(x[:2] / x[2], dtype=np.float64)


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
    centre = approx.mean(axis=0)
    lines = []
    for i in range(sides):
        p, q = approx[i], approx[(i + 1) % sides]
        d = q - p
        length = float(np.linalg.norm(d))
        if length < 6:
            return None
        u = d / length
        along = (pts - p) @ u
        off = (pts - p) @ np.array([-u[1], u[0]])
        near = (along > 0.1 * length) & (along < 0.9 * length) & (np.abs(off) < 0.03 * peri + 2)
        if near.sum() < 5:
            return None
        vx, vy, x0, y0 = cv2.fitLine(pts[near].astype(np.float32), cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
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


# --------------------------------------------------------------------------- boxes


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


# --------------------------------------------------------------------------- labels


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


# --------------------------------------------------------------------------- search


def _parse_roi(roi: tuple[float, float, float, float] | None, shape: tuple[int, ...]
               ) -> tuple[int, int, int, int]:
    h, w = shape[:2]
    if roi is None:
        return 0, 0, w, h
    x0, y0, x1, y1 = (float(v) for v in roi)  # search_area_problem has checked it
    return (max(0, math.floor(x0)), max(0, math.floor(y0)),
            min(w, math.ceil(x1) + 1), min(h, math.ceil(y1) + 1))


def _contains(box: _Box, xy: np.ndarray) -> float:
    """Signed distance (px, positive inside) of xy from the box's outline."""
    return float(cv2.pointPolygonTest(box.hull.astype(np.float32), (float(xy[0]), float(xy[1])), True))


_PNP_MAX = 0.03  # reprojection RMS over the box's image size: above it, not a box


def _box_model(width: float, depth: float, side_face: SideFace) -> dict[str, np.ndarray]:
    """Model corners (height 1; X right, Y down, Z into the object) by point name."""
    pts = {"p1": [0, 0, 0], "p2": [width, 0, 0], "p3": [width, 1, 0], "p6": [0, 1, 0]}
    far = {"right": ([width, 0, depth], [width, 1, depth]), "left": ([0, 0, depth], [0, 1, depth]),
           "top": ([0, 0, depth], [width, 0, depth])}[side_face]
    pts.update(p5=far[0], p7=far[1])
    return {k: np.asarray(v, dtype=np.float64) for k, v in pts.items()}


def _box_likeness(points: dict[str, np.ndarray], side_face: SideFace, shape: tuple[int, ...]) -> float:
    """How far (relative to the box's image size) the points are from any box's projection.

    A quick screen before the engine's fit, which on points that fit no box can take seconds:
    the faces' aspects from their homographies, then a PnP pose for a few focal lengths.
    """
    from prismcore.geometry.faces import clicked_quads
    from prismcore.geometry.perspective import _closed_form

    h, w = shape[:2]
    ref = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in points.items()})
    quads = clicked_quads(ref, two_photo=False, side_face=side_face)
    names = ("p1", "p2", "p3", "p6", "p5", "p7")
    image_pts = np.array([points[n] for n in names])
    size = float(np.linalg.norm(np.ptp(image_pts, axis=0)))
    best = math.inf
    for f in (0.8 * w, 1.2 * w, 2.0 * w, 4.0 * w):
        K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
        try:
            width = _closed_form(K, quads.front)[0]
            aspect = _closed_form(K, quads.side)[0]
        except (np.linalg.LinAlgError, cv2.error):
            continue
        depth = width / aspect if side_face == "top" else aspect
        if not (math.isfinite(width) and math.isfinite(depth) and width > 0 and depth > 0):
            continue
        model = _box_model(width, depth, side_face)
        obj = np.array([model[n] for n in names])
        ok, rvec, tvec = cv2.solvePnP(obj, image_pts, K, None, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            continue
        proj = cv2.projectPoints(obj, rvec, tvec, K, None)[0].reshape(-1, 2)
        best = min(best, float(np.sqrt(np.mean(np.sum((proj - image_pts) ** 2, axis=1)))) / size)
    return best


def _refined(image: np.ndarray, points: dict[str, np.ndarray], side_face: SideFace, *,
             rough: bool = False) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The engine's plan from these points: the fitted box's corners and the plan's fit/edges.

    The focal length is fitted too (from points far from any box that can take the solver
    seconds: `_box_likeness` screens them out first).

    Raises InputError when the plan refuses the points (a fit guard, a degenerate face).
    """
    from prismcore.scan.pipeline import plan_scan

    ref = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in points.items()})
    spec = ScanSpec(image="auto", points=ref, side_face=side_face)
    plan = plan_scan(spec, image, rough_points=rough)
    front, side = plan.faces[0].region, plan.faces[1].region
    if side_face == "right":
        named = {"p4": side[0], "p5": side[1], "p7": side[2]}
    elif side_face == "left":
        named = {"p4": side[1], "p5": side[0], "p7": side[3]}
    else:
        named = {"p4": side[3], "p5": side[0], "p7": side[1]}
    out = {"p1": front[0], "p2": front[1], "p3": front[2], "p6": front[3], **named}
    supports = [f.support if f.fitted else 0.0 for fits in plan.edges.values() for f in fits]
    # Where the fitted edges meet against where the box model puts the corners: the clicks
    # (the previous pass's model corners) cannot tell whether a box explains the edges.
    gaps = []
    for face, region in (("front", front), ("side", side)):
        fits = plan.edges.get(face, [])
        for i in range(len(fits)):
            a, b = fits[i - 1], fits[i]
            if a.fitted and b.fitted:
                with np.errstate(divide="ignore", invalid="ignore"):
                    corner = intersect(a.line, b.line)
                gaps.append(float(np.linalg.norm(corner - region[i])) if np.isfinite(corner).all()
                            else math.inf)
    info = {"fit": plan.fit, "supports": supports, "focal_px": plan.camera.get("focal_px"),
            "perspective": plan.dimensions.perspective, "gaps": gaps}
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}, info


def _confidence(first: dict[str, np.ndarray], second: dict[str, np.ndarray], info: dict[str, Any],
                width: int) -> tuple[float, float]:
    """Confidence 0-1 and the RMS (px) between the two passes' corners."""
    moved = np.array([np.linalg.norm(first[k] - second[k]) for k in first])
    rms = float(np.sqrt(np.mean(moved ** 2)))
    supports = np.asarray(info["supports"], dtype=np.float64)
    # One side partly hidden (a label at the edge, a background of the box's colour) is common
    # and harmless while the box model meets every fitted edge (the gaps term); a side with no
    # edge at all is not.
    weakest = float(np.clip((supports.min() - 0.2) / 0.3, 0, 1))
    c_edges = weakest ** 0.5 * float(np.clip(supports.mean(), 0, 1))
    c_fit = math.exp(-((rms / 1.5) ** 2))
    c_resid = math.exp(-((float(info["fit"].get("rms_px", 0.0)) / 2.5) ** 2))
    gaps = np.asarray(info["gaps"] or [math.inf])
    gap_rms = float(np.sqrt(np.mean(gaps ** 2)))
    c_model = math.exp(-((gap_rms / 1.5) ** 2)) * math.exp(-((float(gaps.max()) / 4.0) ** 2))
    focal = info.get("focal_px")
    c_focal = 1.0 if focal is None or 0.25 * width <= focal <= 6 * width else 0.3
    return float(np.clip(c_edges * c_fit * c_resid * c_model * c_focal, 0, 1)), rms


def find_points(image: np.ndarray, *, hint: tuple[float, float] | None = None,
                roi: tuple[float, float, float, float] | None = None,
                threshold: float = CONFIDENCE_MIN) -> Found:
    """Find a box in a photo and its reference points P1..P7.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        RGB, uint8 (or float 0-255).
    hint : (float, float), optional
        Image (x, y) px on the box wanted: the box whose outline holds it is chosen.
    roi : (x0, y0, x1, y1), optional
        Image px: only a box inside this region is looked for.
    threshold : float
        Results below this confidence carry a reason (are refused).

    Returns
    -------
    Found
        Points in full-image px; `reason` set when the result must not be measured.

    Raises
    ------
    InputError
        For an image that is not RGB, or a hint/roi outside the image.
    """
    timings: dict[str, float] = {}
    start, start_cpu = time.perf_counter(), time.process_time()
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 16:
        raise InputError(f"image must be RGB of shape (H, W, 3), at least 16x16, got {image.shape}")
    h, w = image.shape[:2]
    if (problem := search_area_problem(hint, roi, w, h)) is not None:
        raise InputError(problem[1])
    x0, y0, x1, y1 = _parse_roi(roi, image.shape)
    crop = image[y0:y1, x0:x1]
    scale = min(1.0, WORK_WIDTH / max(crop.shape[1], 1))
    small = crop if scale == 1.0 else cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    small = np.clip(small, 0, 255).astype(np.uint8)
    offset = np.array([x0, y0], dtype=np.float64)

    def full(p: np.ndarray) -> np.ndarray:  # work px -> image px (pixel centres)
        return np.asarray((p + 0.5) / scale - 0.5 + offset, dtype=np.float64)

    quads, silhouettes, work = _all_faces(small)
    boxes = _boxes(quads) + silhouettes
    timings["search"] = (time.perf_counter() - start) * 1000
    # The process's CPU time too: on a shared machine the wall time mostly measures the load.
    timings["search_cpu"] = (time.process_time() - start_cpu) * 1000
    found_faces = tuple(full(q.corners) for q in quads)
    hint_work = None if hint is None else (np.array(hint) - offset + 0.5) * scale - 0.5
    if hint is not None and hint_work is not None and boxes:
        boxes = [b for b in boxes if _contains(b, hint_work) > -3.0]
        if not boxes:
            return Found(None, None, 0.0, f"no box found around the hint ({hint[0]:g},{hint[1]:g})",
                         found_faces, 0, timings_ms=timings)

    def clock() -> None:  # the search's time so far, the corner fits' left out
        timings["search"] = (time.perf_counter() - start) * 1000 - timings.get("fit", 0.0)
        timings["search_cpu"] = ((time.process_time() - start_cpu) * 1000
                                 - timings.get("fit_cpu", 0.0))

    what = "region" if roi is not None else "photo"
    result = _choose(image, boxes, small.shape[:2], full, timings, clock, threshold, hint is not None, what)
    fallbacks: tuple[tuple[str, Callable[[], list[_Box]]], ...] = (
        # One face found, its neighbour's region open: propose the neighbour from lines.
        ("propose", lambda: _proposed_boxes(quads, work, small.shape, hint_work)),
        # Two faces merged into one region, the fold between them too faint for its edges.
        ("split", lambda: _split_boxes(work, small.shape, hint_work)),
    )
    for stage, more_boxes in fallbacks:
        if result is not None and result.ok:
            break
        t0 = time.perf_counter()
        more = more_boxes()
        timings[stage] = (time.perf_counter() - t0) * 1000
        if more:
            other = _choose(image, more, small.shape[:2], full, timings, clock, threshold,
                            hint is not None, what)
            if other is not None and other.ok:
                result = other
    if result is None:
        return Found(None, None, 0.0, _nothing(quads, small.shape), found_faces, 0, timings_ms=timings)
    timings["total"] = (time.perf_counter() - start) * 1000
    return result


_PROPOSE_FROM = 3  # the largest faces (near the centre) a neighbour is proposed for


def _proposed_boxes(quads: list[_Quad], work: _Work, shape: tuple[int, ...],
                    hint_work: np.ndarray | None) -> list[_Box]:
    """Boxes of a face found and a neighbour proposed from the line segments
    (`locate_faces.propose_neighbours`), one per side of each large face."""
    h, w = shape[:2]
    big = [q for q in quads if q.area > 0.02 * h * w]
    if hint_work is not None:
        big = [q for q in big if cv2.pointPolygonTest(q.corners.astype(np.float32),
                                                      (float(hint_work[0]), float(hint_work[1])),
                                                      True) > -0.5 * math.sqrt(q.area)]
    if not big:
        return []
    grad = work.gradient
    centre = np.array([w / 2, h / 2])
    big.sort(key=lambda q: -q.area * (1.0 - 0.6 * np.linalg.norm(q.corners.mean(axis=0) - centre)
                                      / math.hypot(w / 2, h / 2)))
    out = []
    for face in big[:_PROPOSE_FROM]:
        for corners, _ in propose_neighbours(face.corners, work.segments, grad, (h, w)):
            proposed = _clockwise(corners)
            # Proposed from the first sampling's line segments only: not known to be stable.
            proposed.seen = face.seen & 0b01
            faces = [face, proposed]
            allc = np.concatenate([f.corners for f in faces]).astype(np.float32)
            hull = cv2.convexHull(allc).reshape(-1, 2).astype(np.float64)
            out.append(_Box(faces, float(cv2.contourArea(hull.astype(np.float32))), hull.mean(axis=0),
                            hull))
    return out


def _choose(image: np.ndarray, boxes: list[_Box], shape: tuple[int, int],
            full: Callable[[np.ndarray], np.ndarray], timings: dict[str, float],
            clock: Callable[[], None], threshold: float, hinted: bool, what: str) -> Found | None:
    """The best of the candidate boxes measured (None when none passes the PnP screen); a second
    that fits as well makes it ambiguous unless a hint chose."""
    # The quick screen first: pairs of flat shapes that share an edge are no box.
    labelled = []
    for box in boxes:
        named = _label(box)
        if named is None:
            continue
        work, side_face = named
        first_in = {k: full(v) for k, v in work.items()}
        if _box_likeness(first_in, side_face, image.shape) < _PNP_MAX:
            labelled.append((box, first_in, side_face))
    clock()
    if not labelled:
        return None
    labelled.sort(key=lambda item: -_score(item[0], shape[:2]))
    # Boxes built from the same faces (two of a box's three) are one box, not two; but the
    # largest of them is not always the right one (a neighbour proposed on the wrong side, two
    # faces merged into one quad), so the next few over the same place are measured too.
    distinct = [labelled[0]]
    members = [[labelled[0]]]
    for item in labelled[1:]:
        for d, m in zip(distinct, members, strict=True):
            if not (_contains(d[0], item[0].centre) < 0 and _contains(item[0], d[0].centre) < 0):
                m.append(item)
                break
        else:
            distinct.append(item)
            members.append([item])
    result: Found | None = None
    chosen = 0
    tries = [(rank, item) for rank, group in enumerate(members[:_ATTEMPTS]) for item in group[:_PER_CLUSTER]]
    for rank, (box, first_in, side_face) in tries:
        attempt = _measure(image, first_in, side_face, box, full, timings, threshold, len(distinct))
        if result is None or (not result.ok and attempt.confidence > result.confidence):
            result, chosen = attempt, rank
        if attempt.ok:
            break
    assert result is not None
    if result.ok and not hinted:
        best = _score(distinct[chosen][0], shape[:2])
        for box, first_in, side_face in distinct[chosen + 1:chosen + 2]:
            if _score(box, shape[:2]) < _AMBIGUOUS * best:
                break
            other = _measure(image, first_in, side_face, box, full, timings, threshold, len(distinct))
            if other.ok:
                # A second box that fits as well: which one is meant is the caller's to say.
                result = Found(result.points, result.side_face, min(result.confidence, threshold * 0.99),
                               f"2 candidate boxes in the {what}: give a hint (a point on the box "
                               "wanted) or a region", result.faces, len(distinct), result.fit_rms_px,
                               timings)
    return result


def _nothing(quads: list[_Quad], shape: tuple[int, ...]) -> str:
    big = [q for q in quads if q.area > 0.02 * shape[0] * shape[1]]
    if big:
        return "only one face visible: a box needs two faces in the photo (front and a side or the top)"
    return "no box found"


def _measure(image: np.ndarray, first_in: dict[str, np.ndarray], side_face: SideFace, box: _Box,
             full: Callable[[np.ndarray], np.ndarray], timings: dict[str, float], threshold: float,
             candidates: int) -> Found:
    """Place the corners with the engine's plan (twice) and rate them."""
    t0, t0_cpu = time.perf_counter(), time.process_time()

    def clock() -> None:
        timings["fit"] = timings.get("fit", 0.0) + (time.perf_counter() - t0) * 1000
        timings["fit_cpu"] = timings.get("fit_cpu", 0.0) + (time.process_time() - t0_cpu) * 1000

    faces = tuple(full(f.corners) for f in box.faces)
    try:
        first, _ = _refined(image, first_in, side_face, rough=True)
        second, info = _refined(image, first, side_face)
    except InputError as exc:
        clock()
        pts = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in first_in.items()})
        return Found(pts, side_face, 0.0, f"the box found does not fit a box model ({exc})", faces,
                     candidates, None, timings)
    clock()
    confidence, rms = _confidence(first, second, info, image.shape[1])
    h, w = image.shape[:2]
    inside = all(-0.5 <= p[0] <= w - 0.5 and -0.5 <= p[1] <= h - 0.5 for p in second.values())
    if not inside:
        confidence = 0.0
    pts = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in second.items()})
    reason = None
    if confidence < threshold:
        reason = (f"the box found is uncertain (confidence {confidence:.2f} < {threshold:g}): its "
                  "edges are weak or a box does not explain them; give a hint or a region, or "
                  "click the points")
    warnings: tuple[str, ...] = ()
    if reason is None and confidence < CONFIDENCE_WARN:
        warnings = (f"points found automatically with a modest confidence ({confidence:.2f}): "
                    "check them on overlay.png",)
    stable = all(f.seen == _SAMPLINGS for f in box.faces)
    if reason is None and not stable:
        warnings += (_UNSTABLE,)
    return Found(pts, side_face, confidence, reason, faces, candidates, rms, timings, warnings, stable)


_UNSTABLE = ("a face of this box was found in only one of two samplings of the photo (its region "
             "closes on one, not the other): a slight change of the photo may lose the box; check "
             "the points on overlay.png")


def resolve_points(spec: ScanSpec, image: np.ndarray) -> tuple[ScanSpec, Found]:
    """A spec with points "auto" made into one with the points found in `image`.

    Returns the spec to measure (points and side face filled in, `auto_points` cleared) and
    what the search found.

    Raises
    ------
    InputError
        With the search's reason when it refuses (no box, two boxes, one face, uncertain).
    """
    if spec.auto_points is None:
        raise InputError("resolve_points needs a spec with points \"auto\"")
    found = find_points(image, hint=spec.auto_points.hint, roi=spec.auto_points.roi)
    if not found.ok or found.points is None:
        raise InputError(f"points auto: {found.reason}")
    return spec.model_copy(update={"points": found.points, "side_face": found.side_face,
                                   "auto_points": None}), found

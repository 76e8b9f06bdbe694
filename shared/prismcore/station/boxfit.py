"""A box resting on the support, fitted to its silhouette.

With the camera and the support plane known, the box has six unknowns: its footprint's centre
(x, y) and yaw on the plane, its length, width and height. Its silhouette is the convex hull of
its eight projected corners; the fit moves the six until that hull lies on the outline found.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from scipy.optimize import least_squares

__all__ = ["BoxFit", "box_corners", "fit_box", "project"]

_CORRELATION = 4.0  # outline pixels within this many share their error (the JPEG block, the blur)
_MIN_SIGMA_PX = 0.35  # an outline is not known better than this, however smooth it looks
_EDGE_BIAS_PX = 0.5  # the outline's pixel centres lie half a pixel inside the true edge


def box_corners(params: np.ndarray) -> np.ndarray:
    """(8, 3) board-frame corners of the box (x, y, yaw rad, log L, log W, log H): the footprint
    (z = 0) then the top (z = -H: the board's z points into the support)."""
    x, y, yaw, a, b, c = params
    hl, hw, hh = np.exp(a) / 2, np.exp(b) / 2, np.exp(c)
    co, si = np.cos(yaw), np.sin(yaw)
    local = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]])
    xy = local @ np.array([[co, si], [-si, co]]) + (x, y)
    return np.vstack([np.column_stack([xy, np.zeros(4)]), np.column_stack([xy, np.full(4, -hh)])])


def project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Pinhole projection of board-frame points (N, 3) -> image (x, y) px (N, 2)."""
    cam = X @ R.T + t
    return cast("np.ndarray", (cam[:, :2] / cam[:, 2:3]) * (K[0, 0], K[1, 1]) + (K[0, 2], K[1, 2]))


def _hull(pts: np.ndarray) -> np.ndarray:
    """Indices of the convex hull's vertices of (N, 2) points, in order round it."""
    return cv2.convexHull(pts.astype(np.float32), returnPoints=False).ravel()


def _signed_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of each point (N, 2) to a convex polygon's outline (M, 2), negative inside."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a
    ap = points[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("nmk,mk->nm", ap, ab) / np.maximum(np.einsum("mk,mk->m", ab, ab), 1e-12), 0, 1)
    closest = a[None] + t[..., None] * ab[None]
    dist = np.linalg.norm(points[:, None, :] - closest, axis=2).min(axis=1)
    cross = ab[None, :, 0] * ap[..., 1] - ab[None, :, 1] * ap[..., 0]
    orient = np.sign(np.sum(a[:, 0] * np.roll(a[:, 1], -1) - np.roll(a[:, 0], -1) * a[:, 1]))
    inside = np.all(cross * orient >= 0, axis=1)
    return cast("np.ndarray", np.where(inside, -dist, dist))


@dataclass(frozen=True)
class BoxFit:
    """The fitted box.

    params : (6,) x mm, y mm, yaw rad, log length, log width, log height. cov : (6, 6).
    residual_px : RMS distance of the outline from the fitted box's silhouette, px, the worst
        tenth of the outline left out.
    """

    params: np.ndarray
    cov: np.ndarray
    residual_px: float
    outline_px: int

    @property
    def length_mm(self) -> float:
        return float(np.exp(self.params[3]))

    @property
    def width_mm(self) -> float:
        return float(np.exp(self.params[4]))

    @property
    def height_mm(self) -> float:
        return float(np.exp(self.params[5]))

    def sigma_mm(self) -> tuple[float, float, float]:
        """One-sigma of length, width, height, mm."""
        s = np.sqrt(np.maximum(np.diag(self.cov)[3:], 0))
        return (self.length_mm * float(s[0]), self.width_mm * float(s[1]), self.height_mm * float(s[2]))

    def corners(self) -> np.ndarray:
        return box_corners(self.params)


_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
_FACES = {"top": (4, 5, 6, 7), "s0": (0, 1, 5, 4), "s1": (1, 2, 6, 5), "s2": (2, 3, 7, 6), "s3": (3, 0, 4, 7)}
_FOLD_SAMPLES = np.linspace(0.15, 0.85, 8)
_FOLD_CAP_PX = 4.0  # a fold farther than this from any edge pixel is not pulled further


def visible_folds(corners: np.ndarray, camera_centre: np.ndarray) -> list[tuple[int, int]]:
    """Box edges between two faces the camera sees (the folds inside the silhouette)."""
    mid = corners.mean(axis=0)
    seen = []
    for idx in _FACES.values():
        F = corners[list(idx)]
        n = np.cross(F[1] - F[0], F[2] - F[0])
        if n @ (F.mean(axis=0) - mid) < 0:
            n = -n
        if n @ (camera_centre - F.mean(axis=0)) > 0:
            seen.append(set(idx))
    return [(i, j) for i, j in _EDGES if sum({i, j} <= f for f in seen) == 2]


@dataclass(frozen=True)
class _Problem:
    outline: np.ndarray
    outline_poly: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    centre: np.ndarray
    fold_dt: np.ndarray | None  # distance (px) to the nearest edge pixel inside the part, capped
    vertex_weight: float
    fold_weight: float
    edge_bias: float = _EDGE_BIAS_PX


def _lookup(dt: np.ndarray, pts: np.ndarray) -> np.ndarray:
    h, w = dt.shape
    x = np.clip(pts[:, 0], 0, w - 1.001)
    y = np.clip(pts[:, 1], 0, h - 1.001)
    x0, y0 = x.astype(int), y.astype(int)
    fx, fy = x - x0, y - y0
    return cast(
        "np.ndarray",
        (dt[y0, x0] * (1 - fx) + dt[y0, x0 + 1] * fx) * (1 - fy)
        + (dt[y0 + 1, x0] * (1 - fx) + dt[y0 + 1, x0 + 1] * fx) * fy,
    )


def _residuals(params: np.ndarray, p: _Problem) -> np.ndarray:
    X = box_corners(params)
    pts = project(X, p.K, p.R, p.t)
    hull = _hull(pts)
    r1 = _signed_distance(p.outline, pts[hull]) - p.edge_bias
    # Each hull vertex on the outline too, so the hull cannot outgrow it where no outline lies.
    r2 = np.zeros(8)
    for i in hull:
        r2[i] = (
            -cv2.pointPolygonTest(p.outline_poly, (float(pts[i, 0]), float(pts[i, 1])), True) - _EDGE_BIAS_PX
        )
    r3 = np.zeros(3 * len(_FOLD_SAMPLES))
    if p.fold_dt is not None:
        for k, (i, j) in enumerate(visible_folds(X, p.centre)[:3]):
            seg = pts[i] + _FOLD_SAMPLES[:, None] * (pts[j] - pts[i])
            r3[k * len(_FOLD_SAMPLES) : (k + 1) * len(_FOLD_SAMPLES)] = _lookup(p.fold_dt, seg)
    return np.concatenate([r1, p.vertex_weight * r2, p.fold_weight * r3])


def _start(outline: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Starting boxes: the outline cast onto the support, its smallest rectangle shrunk, at a few
    heights."""
    rays = np.column_stack([(outline - (K[0, 2], K[1, 2])) / (K[0, 0], K[1, 1]), np.ones(len(outline))])
    rays_b = rays @ R  # board frame directions (R.T @ ray for each)
    centre = -R.T @ t
    s = -centre[2] / rays_b[:, 2]
    ground = centre[:2] + s[:, None] * rays_b[:, :2]
    (cx, cy), (w, h), ang = cv2.minAreaRect(ground.astype(np.float32))
    starts = []
    for shrink, height, turn in (
        (a, b, c) for a in (0.85, 0.6) for b in (0.3, 0.7, 1.4) for c in (0, 30, 60)
    ):
        if True:
            L, W = max(w * shrink, 1.0), max(h * shrink, 1.0)
            H = max(height * np.sqrt(w * h) * shrink, 1.0)
            # the footprint lies towards the camera's side of the cast outline
            toward = centre[:2] - (cx, cy)
            toward = toward / (np.linalg.norm(toward) + 1e-9) * (1 - shrink) * 0.5 * max(w, h)
            starts.append(
                np.array(
                    [cx + toward[0], cy + toward[1], np.radians(ang + turn), np.log(L), np.log(W), np.log(H)]
                )
            )
    return starts


def fold_distance(gray: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Distance (px, float32, capped) to the nearest intensity edge inside the part: where its
    folds between faces of different shading show."""
    edges = cv2.Canny(gray, 20, 60)
    inner = cv2.erode(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7)))
    edges[inner == 0] = 0
    dt = cv2.distanceTransform((edges == 0).astype(np.uint8), cv2.DIST_L2, 3)
    return cast("np.ndarray", np.minimum(dt, _FOLD_CAP_PX).astype(np.float32))


_PROFILE = np.arange(-4.0, 4.01, 0.5)


def refine_outline(outline: np.ndarray, hull: np.ndarray, difference: np.ndarray) -> np.ndarray:
    """The outline moved, along the fitted silhouette's normals, to where the photo's difference
    from the support crosses halfway between the part's level and the support's: the edge to a
    fraction of a pixel, whatever the threshold that found it. Points with no clear step stay out.

    outline : (N, 2) px. hull : (M, 2) the fitted silhouette, counter-clockwise or not.
    difference : (H, W) float32, the photo's distance from the (shadow-scaled) support.
    """
    a, b = hull, np.roll(hull, -1, axis=0)
    ab = b - a
    ap = outline[:, None, :] - a[None]
    tt = np.clip(np.einsum("nmk,mk->nm", ap, ab) / np.maximum(np.einsum("mk,mk->m", ab, ab), 1e-12), 0, 1)
    near = np.argmin(
        np.linalg.norm(outline[:, None, :] - (a[None] + tt[..., None] * ab[None]), axis=2), axis=1
    )
    d = ab[near] / np.linalg.norm(ab[near], axis=1, keepdims=True)
    normal = np.column_stack([d[:, 1], -d[:, 0]])
    centre = hull.mean(axis=0)
    flip = np.einsum("nk,nk->n", normal, outline - centre) < 0
    normal[flip] *= -1  # outward
    samples = outline[:, None, :] + _PROFILE[None, :, None] * normal[:, None, :]
    prof = _lookup(difference, samples.reshape(-1, 2)).reshape(len(outline), len(_PROFILE))
    inside = np.median(prof[:, :3], axis=1)
    outside = np.median(prof[:, -3:], axis=1)
    level = (inside + outside) / 2
    above = prof >= level[:, None]
    # the last sample above the level, counting outward, and the one after it
    last = len(_PROFILE) - 1 - np.argmax(above[:, ::-1], axis=1)
    ok = (inside - outside > 12) & (last < len(_PROFILE) - 1) & above[:, 0]
    last = np.minimum(last, len(_PROFILE) - 2)
    rows = np.arange(len(outline))
    v0, v1 = prof[rows, last], prof[rows, last + 1]
    frac = np.clip((v0 - level) / np.maximum(v0 - v1, 1e-6), 0, 1)
    offset = _PROFILE[last] + 0.5 * frac
    return cast("np.ndarray", (outline + offset[:, None] * normal)[ok])


def fit_box(
    outline: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    fold_dt: np.ndarray | None = None,
    difference: np.ndarray | None = None,
) -> BoxFit:
    """The box resting on the plane z = 0 whose silhouette (and folds) best match the photo.

    Parameters
    ----------
    outline : ndarray, shape (N, 2), float64
        The silhouette's outline pixels, image (x, y) px of the undistorted photo, in order.
    K : (3, 3) intrinsics. R, t : the plane's pose (board frame -> camera), t in mm.
    fold_dt : ndarray, shape (H, W), float32, optional
        :func:`fold_distance` of the photo: the folds between visible faces are drawn to its edges.
    """
    step = max(1, len(outline) // 200)
    pts = outline[::step]
    centre = -R.T @ t
    simple = cv2.approxPolyDP(outline.astype(np.float32).reshape(-1, 1, 2), 0.7, True)
    problem = _Problem(
        pts,
        simple,
        K,
        R,
        t,
        centre,
        fold_dt,
        vertex_weight=float(np.sqrt(len(pts) / 8) * 0.5),
        fold_weight=float(np.sqrt(len(pts) / 24) * 0.5),
    )
    starts = _start(outline, K, R, t)
    costs = [float(np.sum(np.square(_residuals(s, problem)))) for s in starts]
    best = None
    for i in np.argsort(costs)[:2]:
        sol = least_squares(_residuals, starts[i], args=(problem,), method="lm", x_scale="jac", max_nfev=150)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    if difference is not None:
        hull_pts = project(box_corners(best.x), K, R, t)
        fine = refine_outline(pts, hull_pts[_hull(hull_pts)], difference)
        if len(fine) >= 0.5 * len(pts):
            pts = fine
            problem = _Problem(
                pts,
                simple,
                K,
                R,
                t,
                centre,
                fold_dt,
                problem.vertex_weight,
                problem.fold_weight,
                edge_bias=0.0,
            )
            best = least_squares(
                _residuals, best.x, args=(problem,), method="lm", x_scale="jac", max_nfev=100
            )
    r1 = best.fun[: len(pts)]
    robust = 1.4826 * float(np.median(np.abs(r1 - np.median(r1))))
    sigma = max(_MIN_SIGMA_PX, robust)
    J = np.asarray(best.jac, dtype=np.float64)  # dense: method="lm"
    inflation = max(1.0, _CORRELATION / step)
    try:
        cov = np.linalg.inv(J.T @ J) * sigma**2 * inflation
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.inf)
    params = best.x.copy()
    params[2] = params[2] % np.pi  # yaw in [0, pi): a box turned half a turn is the same box
    # The outline's RMS distance from the box, its worst tenth left out (a shadow's notch, a
    # label's corner): what says whether the part is a box at all.
    trimmed = np.sort(np.abs(r1))[: max(1, int(0.9 * len(r1)))]
    return BoxFit(
        params=params,
        cov=cov,
        residual_px=float(np.sqrt(np.mean(np.square(trimmed)))),
        outline_px=len(outline),
    )

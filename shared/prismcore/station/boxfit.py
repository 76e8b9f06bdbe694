"""A box resting on the support, fitted to its silhouette.

With the camera and the support plane known, the box has six unknowns: its footprint's centre
(x, y) and yaw on the plane, its length, width and height. Its silhouette is the convex hull of
its eight projected corners; the fit moves the six until that hull lies on the outline found.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, cast

import cv2
import numpy as np
from scipy.optimize import least_squares

from prismcore.station.edges import bilinear, refine_outline
from prismcore.station.fit_starts import starting_boxes
from prismcore.station.influence import jackknife_cov, soft_l1_weights

__all__ = ["OutlineFit", "box_corners", "fit_outline_box", "project", "visible_faces"]

_CORRELATION = 4.0  # outline pixels within this many share their error (the JPEG block, the blur)
_MIN_SIGMA_PX = 0.35  # an outline is not known better than this, however smooth it looks
_EDGE_BIAS_PX = 0.5  # the outline's pixel centres lie half a pixel inside the true edge
_COARSE_POINTS = 40  # outline points while choosing among the starts
_DENSE_POINTS = 200
_FITTED_STARTS = 8  # at most
# The starts' fits only choose the basin the dense fit refines: each stops once a step changes its
# cost or its parameters by less than this share (least_squares' default, 1e-8, spent half the fit's
# time on steps that changed no choice).
_COARSE_TOL = 1e-4
_AGREEING = 3  # fits of the starts ending at the best cost: the multi-start stops there
_AGREE = 0.02  # relative cost: the same minimum
_AGREE_SIZE = 0.03  # of the box's largest side: the same box
_WEAK_STEP = 20.0  # RGB levels
_ROBUST_PX = 1.0  # soft-l1 scale of the last fit: outline points farther count less
_MAX_OUTLIERS = 0.10  # of the outline beyond 3 sigma: more, and the fit's sigma is its whole RMS
# A distinct box whose (robust) misfit is within this share of the best one's fits the outline as
# well, as far as an outline with stretches that are not the box's can tell (development set:
# clean fits' rivals cost 3-20 times the best; wrong fits' rivals 1-17 % more)
_RIVAL_COST = 0.15
_RIVAL_SIGMAS = 2.0
_RIVALS = 2  # distinct starts' fits polished and compared, at most


def box_corners(params: np.ndarray) -> np.ndarray:
    """(8, 3) board-frame corners of the box (x, y, yaw rad, log L, log W, log H): the footprint
    (z = 0) then the top (z = -H: the board's z points into the support)."""
    x, y, yaw, a, b, c = params
    with np.errstate(over="ignore", invalid="ignore"):  # a step to an absurd size: not finite, refused
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


def _next(a: np.ndarray) -> np.ndarray:
    """np.roll(a, -1) of a 1-D array (without np.roll's overhead: the fit calls this thousands of times)."""
    return np.concatenate((a[1:], a[:1]))


def _clip(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """np.clip, without its overhead on small arrays."""
    return cast("np.ndarray", np.minimum(np.maximum(a, lo), hi))


@dataclass(frozen=True)
class _Nearest:
    """Where each outline point lies against a convex polygon: its nearest edge `k` (N,), the
    parameter `t` (N,) of its nearest point along that edge (0 at the edge's start, 1 at its end),
    the point from the edge's start `pa` (N, 2), the edge `e` (N, 2) and its squared length (N,),
    the polygon's orientation (+1 or -1: the sign of its shoelace area, x right and y down),
    and the signed distance (N,), negative inside."""

    k: np.ndarray
    t: np.ndarray
    pa: np.ndarray
    e: np.ndarray
    length2: np.ndarray
    orient: float
    signed: np.ndarray


def _nearest(points: np.ndarray, poly: np.ndarray) -> _Nearest:
    """Each point (N, 2) against a convex polygon's outline (M, 2): see :class:`_Nearest`."""
    ax, ay = poly[:, 0], poly[:, 1]
    bx, by = _next(ax), _next(ay)
    ex, ey = bx - ax, by - ay
    px, py = points[:, 0:1] - ax, points[:, 1:2] - ay  # (N, M)
    length2 = np.maximum(ex * ex + ey * ey, 1e-12)
    t = _clip((px * ex + py * ey) / length2, 0.0, 1.0)
    dx, dy = px - t * ex, py - t * ey
    d2 = dx * dx + dy * dy
    k = d2.argmin(axis=1)
    rows = np.arange(len(points))
    dist = np.sqrt(d2[rows, k])
    cross = ex * py - ey * px
    orient = 1.0 if float(np.sum(ax * by - bx * ay)) >= 0 else -1.0
    inside = (cross * orient >= 0).all(axis=1)
    return _Nearest(k=k, t=t[rows, k], pa=np.column_stack([px[rows, k], py[rows, k]]),
                    e=np.column_stack([ex[k], ey[k]]), length2=length2[k], orient=orient,
                    signed=np.where(inside, -dist, dist))


@dataclass(frozen=True)
class OutlineFit:
    """The fitted box.

    params : (6,) x mm, y mm, yaw rad, log length, log width, log height. cov : (6, 6).
    residual_px : RMS distance of the outline from the fitted box's silhouette, px, the worst
        tenth of the outline left out.
    """

    params: np.ndarray
    cov: np.ndarray
    residual_px: float
    outline_px: int
    missing_fraction: float = 0.0  # of the outline lying well inside the box: a stretch not found
    weak_fraction: float = 0.0  # of the fitted silhouette where the photo barely differs across it
    # (3,) mm: how far, in length, width and height, another box fitting the outline almost as well
    # (a distinct minimum of the fit) lies from this one
    ambiguity_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

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
        own = (self.length_mm * float(s[0]), self.width_mm * float(s[1]), self.height_mm * float(s[2]))
        # a rival box fitting as well is taken as lying _RIVAL_SIGMAS sigma away
        both = [float(np.hypot(o, a / _RIVAL_SIGMAS)) for o, a in zip(own, self.ambiguity_mm, strict=True)]
        return (both[0], both[1], both[2])

    def corners(self) -> np.ndarray:
        return box_corners(self.params)


_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
_FACES = {"top": (4, 5, 6, 7), "s0": (0, 1, 5, 4), "s1": (1, 2, 6, 5), "s2": (2, 3, 7, 6), "s3": (3, 0, 4, 7)}
_FOLD_SAMPLES = np.linspace(0.15, 0.85, 8)


def visible_faces(
    corners: np.ndarray, camera_centre: np.ndarray, image_pts: np.ndarray | None = None
) -> dict[str, tuple[tuple[int, ...], float]]:
    """The box's faces the camera sees: {name: (corner indices, area in the image px^2)}, names as
    _FACES ("top", "s0".."s3"). corners : (8, 3) board frame. image_pts : (8, 2) their pixels
    (the areas are 0 without them)."""
    mid = corners.mean(axis=0)
    seen: dict[str, tuple[tuple[int, ...], float]] = {}
    for name, idx in _FACES.items():
        F = corners[list(idx)]
        n = np.cross(F[1] - F[0], F[2] - F[0])
        if n @ (F.mean(axis=0) - mid) < 0:
            n = -n  # outward
        if n @ (camera_centre - F.mean(axis=0)) > 0:
            area = 0.0 if image_pts is None else abs(cv2.contourArea(image_pts[list(idx)].astype(np.float32)))
            seen[name] = (idx, float(area))
    return seen


# The side faces s0..s3 as (their top fold, the vertical fold shared with the next side).
_SIDE_FOLDS = (((4, 5), (1, 5)), ((5, 6), (2, 6)), ((6, 7), (3, 7)), ((7, 4), (0, 4)))


def _folds(params: np.ndarray, camera_centre: np.ndarray) -> list[tuple[int, int]]:
    """The box edges between two faces the camera sees (the folds inside the silhouette), from the
    box's parameters directly (it runs at every step of the fit; tests compare it with
    :func:`visible_faces`)."""
    x, y, yaw, a, b, c = params
    hl, hw = np.exp(a) / 2, np.exp(b) / 2
    dx, dy = camera_centre[0] - x, camera_centre[1] - y
    co, si = np.cos(yaw), np.sin(yaw)
    u, v = dx * co + dy * si, -dx * si + dy * co  # the camera in the box's own axes
    sides = (-v > hw, u > hl, v > hw, -u > hl)  # s0 (y = -hw), s1 (x = +hl), s2, s3
    top = -camera_centre[2] > np.exp(c)
    folds = []
    for k in range(4):
        if sides[k] and top:
            folds.append(_SIDE_FOLDS[k][0])
        if sides[k] and sides[(k + 1) % 4]:
            folds.append(_SIDE_FOLDS[k][1])
    return folds


def _signed_map(outline: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Signed distance (px, float32) to the outline: negative inside, positive outside."""
    inside = np.zeros(shape, np.uint8)
    cv2.fillPoly(inside, [np.round(outline).astype(np.int32).reshape(-1, 1, 2)], 1)
    d_out = cv2.distanceTransform(1 - inside, cv2.DIST_L2, 5)
    d_in = cv2.distanceTransform(inside, cv2.DIST_L2, 5)
    return (d_out - d_in).astype(np.float32)


@dataclass(frozen=True)
class _Problem:
    outline: np.ndarray
    signed: np.ndarray  # _signed_map of the outline, in a window whose origin is `origin`
    origin: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    centre: np.ndarray
    fold_dt: np.ndarray | None  # distance (px) to the nearest edge pixel inside the part, capped
    maps_origin: np.ndarray  # the photo pixel of fold_dt's (0, 0)
    vertex_weight: float
    fold_weight: float
    edge_bias: float = _EDGE_BIAS_PX
    # A box with edges rounded by a radius is its inner box grown by that radius: its silhouette
    # lies this many px (the radius at the part's distance) outside the inner box's.
    rounding_px: float = 0.0
    # The last parameters' projected corners, hull and nearest edges: least_squares asks for the
    # Jacobian where it last evaluated the residuals, and the Jacobian needs the same geometry.
    last: dict[str, Any] = field(default_factory=dict, compare=False)


def _residuals(params: np.ndarray, p: _Problem) -> np.ndarray:
    X = box_corners(params)
    with np.errstate(invalid="ignore"):  # a box of no finite size: refused below
        depth = X @ p.R[2] + p.t[2]
    n = len(p.outline) + 8 + 3 * len(_FOLD_SAMPLES)
    p.last.clear()
    if not (np.all(np.isfinite(X)) and np.all(depth > 1.0)):
        return np.full(n, 1e3)  # a box reaching behind the camera: as far off as can be
    pts = project(X, p.K, p.R, p.t)
    hull = _hull(pts)
    near = _nearest(p.outline, pts[hull])
    p.last.update(key=params.tobytes(), hull=hull, near=near)
    r1 = near.signed - p.edge_bias - p.rounding_px
    # Each hull vertex on the outline too, so the hull cannot outgrow it where no outline lies.
    r2 = np.zeros(8)
    r2[hull] = bilinear(p.signed, pts[hull] - p.origin) - _EDGE_BIAS_PX + p.rounding_px
    r3 = np.zeros(3 * len(_FOLD_SAMPLES))
    if p.fold_dt is not None:
        folds = _fold_ends(params, p.centre)
        if len(folds):
            r3[: len(folds) * len(_FOLD_SAMPLES)] = bilinear(p.fold_dt,
                                                             _fold_samples(pts, folds) - p.maps_origin)
    return np.concatenate([r1, p.vertex_weight * r2, p.fold_weight * r3])


def _fold_ends(params: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(F, 2) corner indices of the (at most three) folds the camera sees."""
    return np.array(_folds(params, centre)[:3], np.intp).reshape(-1, 2)


def _fold_samples(pts: np.ndarray, folds: np.ndarray) -> np.ndarray:
    """(F * S, 2): each fold's _FOLD_SAMPLES points between its projected ends, fold by fold."""
    a, b = pts[folds[:, 0]], pts[folds[:, 1]]
    samples = a[:, None, :] + _FOLD_SAMPLES[None, :, None] * (b - a)[:, None, :]
    return cast("np.ndarray", samples.reshape(-1, 2))


def _lookup_grad(dt: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear value and gradient (d/dx, d/dy) of `dt` at `pts` (N, 2)."""
    h, w = dt.shape
    x = _clip(pts[:, 0], 0, w - 1.001)
    y = _clip(pts[:, 1], 0, h - 1.001)
    x0, y0 = x.astype(np.intp), y.astype(np.intp)
    fx, fy = x - x0, y - y0
    v00, v01, v10, v11 = dt[y0, x0], dt[y0, x0 + 1], dt[y0 + 1, x0], dt[y0 + 1, x0 + 1]
    top, bottom = v00 + (v01 - v00) * fx, v10 + (v11 - v10) * fx
    value = top + (bottom - top) * fy
    gx = (v01 - v00) * (1 - fy) + (v11 - v10) * fy
    gy = bottom - top
    return value, np.stack([gx, gy], axis=1)


def _corner_jacobian(params: np.ndarray, p: _Problem) -> tuple[np.ndarray, np.ndarray]:
    """The 8 projected corners (8, 2) and their derivative by the parameters (8, 2, 6)."""
    x, y, yaw, a, b, c = params
    with np.errstate(over="ignore"):
        hl, hw, hh = np.exp(a) / 2, np.exp(b) / 2, np.exp(c)
    co, si = np.cos(yaw), np.sin(yaw)
    sx = np.array([-1.0, 1.0, 1.0, -1.0])
    sy = np.array([-1.0, -1.0, 1.0, 1.0])
    lx, ly = np.tile(sx * hl, 2), np.tile(sy * hw, 2)
    X = np.column_stack([lx * co - ly * si + x, lx * si + ly * co + y, np.r_[np.zeros(4), np.full(4, -hh)]])
    dX = np.zeros((8, 3, 6))
    dX[:, 0, 0] = 1.0
    dX[:, 1, 1] = 1.0
    dX[:, 0, 2], dX[:, 1, 2] = -lx * si - ly * co, lx * co - ly * si
    dX[:, 0, 3], dX[:, 1, 3] = lx * co, lx * si  # d/d log L: lx scales with hl
    dX[:, 0, 4], dX[:, 1, 4] = -ly * si, ly * co
    dX[4:, 2, 5] = -hh
    cam = X @ p.R.T + p.t
    dcam = np.einsum("ij,njk->nik", p.R, dX)
    z = cam[:, 2]
    fx, fy = p.K[0, 0], p.K[1, 1]
    pts = np.column_stack([fx * cam[:, 0] / z + p.K[0, 2], fy * cam[:, 1] / z + p.K[1, 2]])
    dpts = np.empty((8, 2, 6))
    dpts[:, 0] = fx * (dcam[:, 0] / z[:, None] - cam[:, 0:1] * dcam[:, 2] / (z * z)[:, None])
    dpts[:, 1] = fy * (dcam[:, 1] / z[:, None] - cam[:, 1:2] * dcam[:, 2] / (z * z)[:, None])
    return pts, dpts


def _jacobian(params: np.ndarray, p: _Problem) -> np.ndarray:
    """d(_residuals)/d(params), analytic: each residual's derivative by the corners' pixels (the
    hull's vertices, the folds' ends) chained with the corners' by the parameters."""
    pts, dpts = _corner_jacobian(params, p)
    n = len(p.outline)
    n_fold = 3 * len(_FOLD_SAMPLES)
    J = np.zeros((n + 8 + n_fold, 6))
    if not (np.all(np.isfinite(pts))):
        return J
    if p.last.get("key") != params.tobytes():
        _residuals(params, p)
        if "near" not in p.last:
            return J
    hull, near = p.last["hull"], p.last["near"]
    k, tk, pa, ek, orient = near.k, near.t, near.pa, near.e, near.orient
    el = np.sqrt(near.length2)
    # the outward normal of a counter-clockwise (orient > 0, y down) edge is (ey, -ex) / |e|
    nrm = -orient * np.column_stack([-ek[:, 1], ek[:, 0]]) / el[:, None]
    d_s = np.sum(nrm * pa, axis=1)
    # d n / d e = (Jr - n ê^T) / |e| with Jr the rotation n = Jr e / |e|
    jr = -orient * np.array([[0.0, -1.0], [1.0, 0.0]])
    e_hat = ek / el[:, None]
    g_e = (pa @ jr) - d_s[:, None] * e_hat  # (p - a)^T (Jr - n ê^T), per point
    g_e /= el[:, None]
    d_a = -nrm - g_e
    d_b = g_e
    interior = (tk > 0) & (tk < 1)
    # in a vertex's region the distance is to the vertex itself (outside: positive)
    at_b = ~interior & (tk >= 1)
    dist = np.linalg.norm(pa - tk[:, None] * ek, axis=1)
    away = (pa - tk[:, None] * ek) / np.maximum(dist, 1e-9)[:, None]
    d_a = np.where((~interior & ~at_b)[:, None], -away, d_a)
    d_b = np.where(at_b[:, None], -away, np.where(interior[:, None], d_b, 0.0))
    ia = hull[k]
    ib = hull[(k + 1) % len(hull)]
    da, db = dpts[ia], dpts[ib]
    J[:n] = d_a[:, 0:1] * da[:, 0] + d_a[:, 1:2] * da[:, 1] + d_b[:, 0:1] * db[:, 0] + d_b[:, 1:2] * db[:, 1]
    _, g = _lookup_grad(p.signed, pts[hull] - p.origin)
    J[n + hull] = p.vertex_weight * np.einsum("nk,nkp->np", g, dpts[hull])
    if p.fold_dt is not None:
        folds = _fold_ends(params, p.centre)
        if len(folds):
            _, g = _lookup_grad(p.fold_dt, _fold_samples(pts, folds) - p.maps_origin)
            g = g.reshape(len(folds), len(_FOLD_SAMPLES), 2)
            s = _FOLD_SAMPLES[None, :, None]
            block = (np.einsum("fnk,fkp->fnp", g * (1 - s), dpts[folds[:, 0]])
                     + np.einsum("fnk,fkp->fnp", g * s, dpts[folds[:, 1]]))
            J[n + 8: n + 8 + len(folds) * len(_FOLD_SAMPLES)] = p.fold_weight * block.reshape(-1, 6)
    return J


def _same_box(a: np.ndarray, b: np.ndarray) -> bool:
    """Two fitted parameter sets the same box within _AGREE_SIZE: footprint sides (in either order:
    a box turned a quarter with its sides swapped is the same box), height and centre."""
    sa = np.r_[np.sort(np.exp(a[3:5])), np.exp(a[5])]
    sb = np.r_[np.sort(np.exp(b[3:5])), np.exp(b[5])]
    tol = _AGREE_SIZE * float(max(sa.max(), sb.max()))
    return bool(np.all(np.abs(sa - sb) <= tol) and np.hypot(a[0] - b[0], a[1] - b[1]) <= tol)


def _weak_fraction(corners_px: np.ndarray, difference: np.ndarray) -> float:
    """The share of the fitted silhouette's outline across which the photo's difference from the
    support steps by less than _WEAK_STEP levels (3 px in against 3 px out): where a part's
    colour meets the support's, its edge may have been found short of where it is."""
    hull = corners_px[_hull(corners_px)]
    centre = hull.mean(axis=0)
    s = np.linspace(0.05, 0.95, 20)[:, None]
    pts = np.concatenate([a + s * (b - a) for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True)])
    inward = (centre - pts) / np.maximum(np.linalg.norm(centre - pts, axis=1), 1e-9)[:, None]
    step = bilinear(difference, pts + 3 * inward) - bilinear(difference, pts - 3 * inward)
    return float(np.mean(step < _WEAK_STEP))


def fit_outline_box(
    outline: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    fold_dt: np.ndarray | None = None,
    difference: np.ndarray | None = None,
    origin: tuple[int, int] = (0, 0),
    radius_mm: float = 0.0,
) -> OutlineFit:
    """The box resting on the plane z = 0 whose silhouette (and folds) best match the photo.

    Parameters
    ----------
    outline : ndarray, shape (N, 2), float64
        The silhouette's outline pixels, image (x, y) px of the undistorted photo, in order.
    K : (3, 3) intrinsics. R, t : the plane's pose (board frame -> camera), t in mm.
    fold_dt : ndarray, shape (H, W), float32, optional
        :func:`fold_distance` of the photo: the folds between visible faces are drawn to its edges.
    difference : ndarray, shape (H, W), float32, optional
        The photo's distance from the support (:class:`~prismcore.station.segment.Silhouette`'s):
        the outline is refined to where it steps.
    origin : the photo pixel (x, y) of `fold_dt`'s and `difference`'s (0, 0) (a window of the photo).
    radius_mm : the radius of the box's rounded edges, mm. The box fitted is then the inner box
        (every side 2 radii shorter, raised by one radius) whose silhouette grown by the radius
        (at the part's distance) is the outline; the fit returned is the outer box's.
    """
    if radius_mm > 0:
        inner = _fit(outline, K, R, t - radius_mm * R[:, 2], fold_dt, difference, origin, radius_mm)
        return _outer(inner, radius_mm)
    return _fit(outline, K, R, t, fold_dt, difference, origin)


def _radius_px(radius_mm: float, params: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> float:
    """`radius_mm` at the distance of the box `params`' centre, px."""
    if radius_mm <= 0:
        return 0.0
    depth = float(np.mean(box_corners(params) @ R[2] + t[2]))
    return radius_mm * float(K[0, 0]) / max(depth, 1.0)


def _outer(inner: OutlineFit, radius_mm: float) -> OutlineFit:
    """The box whose edges, rounded by `radius_mm`, enclose `inner` grown by that radius."""
    params = inner.params.copy()
    size = np.exp(params[3:]) + 2 * radius_mm
    params[3:] = np.log(size)
    # d log(e^a + 2r) / d a: the log-sides' covariance carried over
    if not np.all(np.isfinite(inner.cov)):
        return replace(inner, params=params, cov=np.full((6, 6), np.inf))
    J = np.diag(np.r_[np.ones(3), np.exp(inner.params[3:]) / size])
    return replace(inner, params=params, cov=J @ inner.cov @ J.T)


def _widened(cov: np.ndarray, x: np.ndarray, r: np.ndarray, p: _Problem, noise_var: float) -> np.ndarray:
    """`cov` widened, parameter by parameter, to the spread of the fits that leave out one side of
    the silhouette (or the folds) at a time, where that spread is the larger: sides that disagree
    (a shadow or a mirrored face taken for the part, a face lost against the support) show in it,
    where the outline's noise alone does not."""
    if not np.all(np.isfinite(cov)):
        return cov
    pts = project(box_corners(x), p.K, p.R, p.t)
    near = _nearest(p.outline, pts[_hull(pts)])
    groups = [np.flatnonzero(near.k == k) for k in np.unique(near.k)]
    folds = len(p.outline) + 8 + np.arange(3 * len(_FOLD_SAMPLES))
    J = _jacobian(x, p)
    if np.any(J[folds] != 0):
        groups.append(folds)
    jack = jackknife_cov(J, r, soft_l1_weights(r, _ROBUST_PX), groups, noise_var)
    scale = np.sqrt(np.maximum(1.0, np.diag(jack) / np.maximum(np.diag(cov), 1e-300)))
    return cast("np.ndarray", cov * np.outer(scale, scale))


def _rivals(best: Any, starts: list[np.ndarray], p: _Problem) -> tuple[float, float, float]:
    """How far (mm, per length, width, height of `best`) the distinct boxes among the starts' fits
    lie from `best` where they fit within _RIVAL_COST of its cost, both polished on the final
    outline thinned to _COARSE_POINTS (on all of it they doubled the fit's time)."""
    n = max(1, len(p.outline) // _COARSE_POINTS)
    pts = p.outline[::n]
    sparse = replace(p, outline=pts, vertex_weight=float(np.sqrt(len(pts) / 8) * 0.5),
                     fold_weight=float(np.sqrt(len(pts) / 24) * 0.5), last={})

    def polish(x: np.ndarray, nfev: int) -> Any:
        return least_squares(_residuals, x, jac=_jacobian, args=(sparse,), method="lm", x_scale="jac",
                             max_nfev=nfev, ftol=_COARSE_TOL, xtol=_COARSE_TOL)

    spread, size, tried, base = np.zeros(3), np.exp(best.x[3:]), 0, None
    for x in starts:
        if tried >= _RIVALS or _same_box(x, best.x):
            continue
        tried += 1
        base = polish(best.x, 10) if base is None else base
        rival = polish(x, 20)
        if _same_box(rival.x, best.x) or rival.cost > (1 + _RIVAL_COST) * base.cost:
            continue
        other = np.exp(rival.x[3:])
        if (other[0] >= other[1]) != (size[0] >= size[1]):
            other[:2] = other[1::-1]  # the same sides, named as in `best` (a box turned a quarter)
        spread = np.maximum(spread, np.abs(other - size))
    return (float(spread[0]), float(spread[1]), float(spread[2]))


def _fit(outline: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, fold_dt: np.ndarray | None,
         difference: np.ndarray | None, origin: tuple[int, int], rounding_mm: float = 0.0) -> OutlineFit:
    centre = -R.T @ t
    maps_o = np.asarray(origin, np.float64)
    lo = np.floor(outline.min(axis=0)) - 20
    hi = np.ceil(outline.max(axis=0)) + 20
    signed = _signed_map(outline - lo, (int(hi[1] - lo[1]), int(hi[0] - lo[0])))

    def problem(n_points: int, pts: np.ndarray | None = None, edge_bias: float = _EDGE_BIAS_PX) -> _Problem:
        if pts is None:
            pts = outline[:: max(1, len(outline) // n_points)]
        return _Problem(pts, signed, lo, K, R, t, centre, fold_dt, maps_o,
                        vertex_weight=float(np.sqrt(len(pts) / 8) * 0.5),
                        fold_weight=float(np.sqrt(len(pts) / 24) * 0.5), edge_bias=edge_bias,
                        rounding_px=rounding_px)

    # Every start scored, the best few fitted on a sparse outline, the best of those on a dense one:
    # the silhouette alone has local minima (the box turned a quarter with its sides swapped).
    starts = starting_boxes(outline, K, R, t)
    rounding_px = _radius_px(rounding_mm, starts[0], K, R, t)
    coarse = problem(_COARSE_POINTS)
    costs = [float(np.sum(np.square(_residuals(s, coarse)))) for s in starts]
    # Fitted best first, until _AGREEING of them end at the best one yet (the same box at the same
    # cost, reached from different starts), or _FITTED_STARTS are fitted.
    fits: list[Any] = []
    for i in np.argsort(costs)[:_FITTED_STARTS]:
        fits.append(least_squares(_residuals, starts[i], jac=_jacobian, args=(coarse,), method="lm",
                                  x_scale="jac", max_nfev=25, ftol=_COARSE_TOL, xtol=_COARSE_TOL))
        lowest = min(fits, key=lambda f: f.cost)
        if sum(f.cost <= lowest.cost * (1 + _AGREE) and _same_box(f.x, lowest.x) for f in fits) >= _AGREEING:
            break
    best_x = min(fits, key=lambda f: f.cost).x
    rounding_px = _radius_px(rounding_mm, best_x, K, R, t)
    dense = problem(_DENSE_POINTS)
    best = least_squares(_residuals, best_x, jac=_jacobian, args=(dense,), method="lm", x_scale="jac",
                         max_nfev=60)
    pts = dense.outline
    step = max(1, len(outline) // _DENSE_POINTS)
    if difference is not None:
        hull_pts = project(box_corners(best.x), K, R, t)
        fine = refine_outline(pts - maps_o, hull_pts[_hull(hull_pts)] - maps_o, difference) + maps_o
        if len(fine) >= 0.5 * len(pts):
            pts = fine
            dense = problem(0, fine, 0.0)
    # Robustly at the end: where the part's colour meets the support's, a stretch of its outline
    # is missing or dented, and those points should not pull the box in.
    best = least_squares(_residuals, best.x, jac=_jacobian, args=(dense,), method="trf", loss="soft_l1",
                         f_scale=_ROBUST_PX, x_scale="jac", max_nfev=80)
    r1 = best.fun[: len(pts)]
    robust = 1.4826 * float(np.median(np.abs(r1 - np.median(r1))))
    sigma = max(_MIN_SIGMA_PX, robust)
    missing = float(np.mean(r1 < -3 * sigma))  # by the robust sigma: the outline the box leaves out
    J = np.asarray(best.jac, dtype=np.float64)  # dense: method="trf" without a sparsity pattern
    keep = np.ones(len(best.fun), bool)
    keep[: len(pts)] = np.abs(r1) <= 3 * sigma  # the outline's outliers carry no weight at the end
    if 1.0 - float(np.mean(keep[: len(pts)])) > _MAX_OUTLIERS:
        # A robust fit's covariance holds when its outliers are few. Past that, the box is not
        # what the outline says (a face merged with the support, found in part): the sigma is the
        # whole outline's RMS distance from the box, every point weighed (the Jacobian without the
        # robust loss, which least_squares' own has scaled down).
        J = _jacobian(best.x, dense)
        keep[:] = True
        sigma = max(sigma, float(np.sqrt(np.mean(np.square(r1)))))
    J = J[keep]
    inflation = max(1.0, _CORRELATION / step)
    try:
        cov = np.linalg.inv(J.T @ J) * sigma**2 * inflation
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.inf)
    cov = _widened(cov, best.x, best.fun, dense, sigma**2 * inflation)
    params = best.x.copy()
    params[2] = params[2] % np.pi  # yaw in [0, pi): a box turned half a turn is the same box
    # The outline's RMS distance from the box, its worst tenth left out (a shadow's notch, a
    # label's corner): what says whether the part is a box at all.
    trimmed = np.sort(np.abs(r1))[: max(1, int(0.9 * len(r1)))]
    # the rivals: the other starts' fits, then the starts not fitted (the multi-start stopped once
    # its best agreed), by their cost
    unfitted = [starts[i] for i in np.argsort(costs)[len(fits):]]
    ambiguity = _rivals(best, [f.x for f in sorted(fits, key=lambda f: f.cost)] + unfitted, dense)
    weak = 0.0 if difference is None else _weak_fraction(project(box_corners(best.x), K, R, t) - maps_o,
                                                         difference)
    return OutlineFit(
        missing_fraction=missing,
        weak_fraction=weak,
        params=params,
        cov=cov,
        residual_px=float(np.sqrt(np.mean(np.square(trimmed)))),
        outline_px=len(outline),
        ambiguity_mm=ambiguity,
    )

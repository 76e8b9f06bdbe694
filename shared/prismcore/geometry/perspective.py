"""Pinhole fits of a rectangle or a box to the fitted edge lines of its faces.

Corners found by intersecting fitted lines are ill-conditioned when two sides meet at a small
angle (a side face seen nearly edge-on). So the model is fitted to the lines themselves: each
model edge's projected end points must lie on its fitted line (sigma 0.3 px), and each model
corner is pulled weakly towards its click (sigma 5 px), which only decides what the lines leave
open. Sides where no edge was found contribute through the clicks alone; a side fitted to the
wrong edge is outvoted by the others through a robust (Cauchy) loss.

A box (front and side face in one photo) shows three mutually orthogonal edge directions, which
over-determine the focal length: when none is known it is a free parameter of the box fit,
started from the vanishing points' closed form. Every fit is started several times (focal
candidates, poses from either face) and the lowest cost wins, so that neighbouring inputs land
in the same minimum. The starts' work is bounded (`BoxFit.nfev`): on points that are no box
they slide towards the focal length's bound without converging.

The second face may be the right side (the paper's), the left side (in the plane X = 0) or the
top (in the plane Y = 0): see `prismcore.geometry.faces` for which corner each point marks.

The lens distortion the edges show is `prismcore.geometry.lens`, the evidence undistorted for a
fit `prismcore.geometry.evidence`; what the model leaves out (that distortion, rounded edges) as
the shape's covariance, `prismcore.geometry.model_error`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from prismcore.geometry.box_model import FRONT_IDX, SECOND_FACES, camera_matrix
from prismcore.geometry.lens import RadialDistortion

__all__ = [
    "F_SCALE",
    "NOISE_CLICK_PX",
    "NOISE_LINE_PX",
    "SIGMA_CLICK_PX",
    "SIGMA_LINE_PX",
    "BoxFit",
    "FaceEvidence",
    "FaceTerms",
    "cauchy_weights",
    "centre_depth",
    "fit_box",
    "fit_rectangle",
    "focal_from_vanishing_points",
    "line_terms",
    "n_line_terms",
    "project",
    "rectangle_pose",
    "residual_and_jacobian",
]

SIGMA_LINE_PX = 0.3
SIGMA_CLICK_PX = 5.0
NOISE_CLICK_PX = 1.5
"""Assumed 1-sigma error of a click (px, per axis), for the fit's covariance."""
NOISE_LINE_PX = 0.5
"""Assumed 1-sigma error of a fitted edge line at a model corner (px), for the covariance."""
_UNIT_SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32)
F_SCALE = 3.0
"""The Cauchy loss's scale (whitened residuals): beyond it a residual counts less and less."""
# Multi-start focal candidates, as multiples of the image's larger side (phones: ~0.7-1.0).
_FOCAL_STARTS = (0.6, 0.9, 1.3, 2.0, 3.5)
_FOCAL_BOUNDS = (0.05, 50.0)  # plausible focal range, multiples of the larger side


@dataclass(frozen=True)
class FaceEvidence:
    """What the image says about one face.

    corners : (4, 2) TL, TR, BR, BL image (x, y) px, from intersecting the fitted lines
    clicked : (4, 2) the same corners as clicked
    lines : four (a, b, c) lines (top, right, bottom, left), None where no edge was found
    samples : per side, (N, 2) image (x, y) px along the edge as photographed (`EdgeFit.points`),
        None where there are none; empty when not given. They let the lens's distortion be read
        from how the edges bend (`estimate_distortion`).
    """

    corners: np.ndarray
    clicked: np.ndarray
    lines: tuple[np.ndarray | None, ...]
    samples: tuple[np.ndarray | None, ...] = ()


@dataclass(frozen=True)
class BoxFit:
    """A box fitted to a front and a side face in one photo (height 1).

    width, depth : float
        In units of the height.
    rvec, tvec : ndarray, shape (3,)
        World-to-camera pose (Rodrigues vector; translation in units of the height).
    focal_px : float
        The focal length used (fitted when `focal_std_px` is not None).
    focal_std_px : float or None
        1-sigma error of a fitted focal length, px; None when it was given.
    front_quad, side_quad : ndarray, shape (4, 2)
        The fitted model's projected face corners (TL, TR, BR, BL as photographed).
    shape_cov : ndarray, shape (4, 4)
        Covariance of (width, depth, z, focal_px), z the depth of the front face's centre
        along the optical axis (height units), under click noise NOISE_CLICK_PX and edge-line
        noise NOISE_LINE_PX. The focal row and column are zero when it was given.
    line_rms_px : float
        RMS distance (px) of the model's edge end points from the fitted edge lines.
    influence : ndarray, shape (4, n_residuals)
        d(width, depth, z, focal_px) / d(whitened residuals) at the solution (robust weights
        frozen): how a systematic shift of the data (an unmodelled lens distortion, a rounded
        edge's silhouette) moves the shape; see `model_error_cov`.
    principal : ndarray, shape (2,)
        The principal point (x, y) px the fit used.
    lens : RadialDistortion or None
        The lens distortion removed from the evidence before the fit (`measure.measure_box`).
    nfev : int
        Residual evaluations the solver made, summed over every start (the Jacobian, in
        closed form, evaluated besides): the fit's work, independent of the machine's load.
    """

    width: float
    depth: float
    rvec: np.ndarray
    tvec: np.ndarray
    focal_px: float
    focal_std_px: float | None
    front_quad: np.ndarray
    side_quad: np.ndarray
    shape_cov: np.ndarray
    line_rms_px: float
    influence: np.ndarray | None = None
    principal: np.ndarray | None = None
    lens: RadialDistortion | None = None
    nfev: int = 0

    @property
    def centre_depth(self) -> float:
        """Depth along the optical axis of the front face's centre (height units)."""
        return centre_depth(self.rvec, self.tvec, self.width)


def project(K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Project world points (N, 3) to image (x, y) px, shape (N, 2)."""
    cam = pts @ cv2.Rodrigues(rvec)[0].T + tvec
    uv = cam @ K.T
    xy: np.ndarray = uv[:, :2] / uv[:, 2:3]
    return xy


def centre_depth(rvec: np.ndarray, tvec: np.ndarray, width: float) -> float:
    """Depth along the optical axis of the front face's centre (height units), given a pose."""
    R = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    return float((R @ np.array([width / 2, 0.5, 0.0]) + tvec)[2])


def rectangle_pose(K: np.ndarray, quad: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Aspect and pose (height 1) of a rectangle imaged as `quad`, from its homography."""
    H = cv2.getPerspectiveTransform(_UNIT_SQUARE, quad.astype(np.float32))
    M = np.linalg.solve(K, H)
    if M[2, 2] < 0:  # the plane must lie in front of the camera
        M = -M
    a1, a2, a3 = M.T
    lam = np.linalg.norm(a2)
    r1, r2 = a1 / np.linalg.norm(a1), a2 / lam
    U, _, Vt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=1))
    return float(np.linalg.norm(a1) / lam), cv2.Rodrigues(U @ Vt)[0].ravel(), a3 / lam


FaceTerms = list[tuple[FaceEvidence, tuple[int, ...], tuple[int, ...]]]


def line_terms(faces: FaceTerms) -> list[tuple[int, int, np.ndarray, int]]:
    """The line residuals' layout, the one every user of it reads (the residuals, their count,
    the model's error patterns): per face, per side used that has a fitted line, one term per
    end of that side; each (face index, side, line (a, b, c) as float64, model corner)."""
    return [(f, s, np.asarray(line, dtype=np.float64), idx[e])
            for f, (face, idx, sides) in enumerate(faces) for s in sides
            if (line := face.lines[s]) is not None
            for e in (s, (s + 1) % 4)]


def cauchy_weights(fun: np.ndarray) -> np.ndarray:
    """The Cauchy loss's IRLS weights 1 / (1 + (r / F_SCALE)^2) of whitened residuals `fun`
    (n,): how much each residual counts at a robust fit's solution."""
    w: np.ndarray = 1.0 / (1.0 + (np.asarray(fun) / F_SCALE) ** 2)
    return w


def residual_and_jacobian(K_of: Callable[[np.ndarray], np.ndarray],
                          corners_of: Callable[[np.ndarray], np.ndarray],
                          n_shape: int, faces: FaceTerms, *, log_focal: bool = False
                          ) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """Whitened residuals, line terms (sigma SIGMA_LINE_PX) then click terms (SIGMA_CLICK_PX),
    vectorised, and their Jacobian in closed form: the solver's finite differences took ten
    residual evaluations per step, most of a free-focal box fit's time. faces: (evidence, model
    corner index of TL, TR, BR, BL, sides of the face to use); x = rvec (3), tvec (3), shape
    (n_shape), then whatever K_of reads (e.g. log focal). `corners_of` must be affine in the shape (the
    box models are); with `log_focal`, x[6 + n_shape] is the log of a focal length K_of puts on the
    diagonal (fx = fy = f about a fixed principal point)."""
    rows = line_terms(faces)
    click_idx: list[int] = []
    clicked: list[np.ndarray] = []
    for face, idx, _ in faces:
        click_idx += list(idx)
        clicked.append(np.asarray(face.clicked, dtype=np.float64))
    ends = np.array([corner for *_, corner in rows], dtype=int)
    coef = np.array([line for _, _, line, _ in rows], dtype=np.float64).reshape(-1, 3)
    clicks = np.array(click_idx, dtype=int)
    target = np.concatenate(clicked).reshape(-1, 2)

    def fun_of(pts: np.ndarray) -> np.ndarray:
        lines = ((pts[ends] * coef[:, :2]).sum(axis=1) + coef[:, 2]) / SIGMA_LINE_PX
        return np.concatenate([lines, ((pts[clicks] - target) / SIGMA_CLICK_PX).ravel()])

    def residual(x: np.ndarray) -> np.ndarray:
        return fun_of(project(K_of(x), x[:3], x[3:6], corners_of(x[6:6 + n_shape])))

    def jacobian(x: np.ndarray) -> np.ndarray:
        K = K_of(x)
        shape = x[6:6 + n_shape]
        world = corners_of(shape)
        d_world = np.stack([corners_of(shape + e) - world for e in np.eye(n_shape)], axis=-1)  # (N, 3, S)
        R, dR = cv2.Rodrigues(np.asarray(x[:3], dtype=np.float64))
        cam = world @ R.T + x[3:6]
        uv = cam @ K.T
        pts = uv[:, :2] / uv[:, 2:3]
        # d(pts)/d(cam): (K[:2] - pts K[2]) / (K cam)[2], (N, 2, 3).
        d_pts = (K[None, :2, :] - pts[:, :, None] * K[None, 2:3, :]) / uv[:, 2, None, None]
        d_cam = np.concatenate([
            np.einsum("kij,nj->nik", dR.reshape(3, 3, 3), world),  # rvec
            np.broadcast_to(np.eye(3), (world.shape[0], 3, 3)),  # tvec
            np.einsum("ij,njs->nis", R, d_world),  # shape
        ], axis=2)
        J = np.einsum("nij,njk->nik", d_pts, d_cam)  # (N, 2, 6 + S)
        if log_focal:
            J = np.concatenate([J, (pts - K[:2, 2])[:, :, None]], axis=2)
        J = np.concatenate([J, np.zeros((*J.shape[:2], x.size - J.shape[2]))], axis=2)
        lines = (J[ends] * coef[:, :2, None]).sum(axis=1) / SIGMA_LINE_PX
        out: np.ndarray = np.concatenate([lines, J[clicks].reshape(-1, x.size) / SIGMA_CLICK_PX])
        return out

    return residual, jacobian


_ACCEPT = 4.0  # a fit costing up to this many times what the assumed noise explains is taken
# A start that has not converged after this many evaluations is sliding along a valley the data do
# not close (the focal length running to its bound with the depth running off to infinity, on
# points that are no box): where it stops is arbitrary anyway, and the solver's own limit (100
# per parameter) made one such fit take minutes. Converged starts take under 300: with the
# closed-form Jacobian, `benchmarks/fit_work.py --scenes 40` (every fit the zero-click search
# makes, 117 fits) counts 9 evaluations a fit at the median, 46 at p90 and 326 at worst, summed
# over its starts (5 / 17 / 116 ms CPU); photo-like renders 10-36 a start. The real video's
# slowest start took 259 when the Jacobian was still finite differences.
_MAX_NFEV = 300
# The free-focal fit tries no further start once its starts have made this many evaluations
# together (the real video's worst consistent fit took about 900, with finite differences).
_NFEV_BUDGET = 1500


def _expected_cost(faces: FaceTerms, n_lines: int) -> float:
    """The solver's cost (half the sum of squared whitened residuals) that the assumed click
    and line noise alone would give."""
    n_clicks = 8 * len(faces)
    return 0.5 * (n_lines * (NOISE_LINE_PX / SIGMA_LINE_PX) ** 2
                  + n_clicks * (NOISE_CLICK_PX / SIGMA_CLICK_PX) ** 2)


def n_line_terms(faces: FaceTerms) -> int:
    """How many line residuals `faces` give (`line_terms`)."""
    return len(line_terms(faces))


def _solve(residual: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
           bounds: tuple[np.ndarray, np.ndarray] | None = None,
           jac: Callable[[np.ndarray], np.ndarray] | None = None) -> OptimizeResult:
    # A robust loss: one side fitted to the wrong edge (it happens on a face seen nearly
    # edge-on) must not drag the box, which the other sides and the clicks hold in place.
    kw: dict[str, Any] = {} if bounds is None else {"bounds": bounds}
    if jac is not None:
        kw["jac"] = jac
    return least_squares(residual, x0, method="trf", x_scale="jac", loss="cauchy",
                         f_scale=F_SCALE, max_nfev=_MAX_NFEV, **kw)


def _covariance(res: OptimizeResult, n_lines: int) -> np.ndarray:
    """Parameter covariance under the assumed click and line noise (sandwich estimator).

    The solver's sigmas weigh the terms (clicks only decide what the lines leave open); the
    data's noise is NOISE_*: with whitened Jacobian J and robust weights w,
    cov = A^-1 J^T W N W J A^-1, A = J^T W J, N the data noise over the solver's sigma squared.
    Where the residuals scatter more than that noise explains, N is scaled up by the weighted
    residuals' variance factor (never down): real clicks and edges that disagree with one box
    (a printed border taken for an edge, a mark a few px off) make the answer that much less
    sure, and the assumed noise alone claimed a 2-sigma interval that missed half the real
    video's frames.
    """
    J = np.asarray(res.jac, dtype=np.float64)
    w = cauchy_weights(res.fun)
    noise = np.full(J.shape[0], (NOISE_CLICK_PX / SIGMA_CLICK_PX) ** 2)
    noise[:n_lines] = (NOISE_LINE_PX / SIGMA_LINE_PX) ** 2
    Jw = J * w[:, None]
    A = J.T @ Jw
    A_inv = np.linalg.pinv(A, rcond=1e-12)
    B = Jw.T @ (Jw * noise[:, None])
    cov: np.ndarray = A_inv @ B @ A_inv
    return cov * _variance_factor(res.fun, w, noise, res.x.size)


def _variance_factor(fun: np.ndarray, w: np.ndarray, noise: np.ndarray, n_params: int) -> float:
    """Weighted residual variance over the assumed noise's, at least 1 (1 when nothing is
    over-determined). The robust weights keep one outlier, which the fit already discounts,
    from inflating every dimension."""
    dof = float(w.sum()) - n_params
    if dof < 1.0:
        return 1.0
    return max(1.0, float(np.sum(w * fun ** 2 / noise)) / dof)


def _influence(res: OptimizeResult) -> np.ndarray:
    """dx / d(whitened residuals), (n_params, n_residuals): the linearised shift of the solution
    when the data move (robust weights frozen), -(J^T W J)^-1 J^T W."""
    J = np.asarray(res.jac, dtype=np.float64)
    Jw = J * cauchy_weights(res.fun)[:, None]
    influence: np.ndarray = -np.linalg.pinv(J.T @ Jw, rcond=1e-12) @ Jw.T
    return influence


def _line_rms(res: OptimizeResult, n_lines: int) -> float:
    if n_lines == 0:
        return 0.0
    return float(np.sqrt(np.mean((res.fun[:n_lines] * SIGMA_LINE_PX) ** 2)))


def fit_rectangle(K: np.ndarray, face: FaceEvidence) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Aspect (width / height) and pose of a rectangle, its height = 1.

    Returns
    -------
    aspect : float
    rvec, tvec : ndarray, shape (3,)
    quad : ndarray, shape (4, 2)
        The fitted rectangle's projected corners.
    """
    aspect, rvec, tvec = rectangle_pose(K, face.corners)

    def corners_of(p: np.ndarray) -> np.ndarray:
        return np.array([[0, 0, 0], [p[0], 0, 0], [p[0], 1, 0], [0, 1, 0]], dtype=np.float64)

    residual, _ = residual_and_jacobian(lambda _: K, corners_of, 1, [(face, (0, 1, 2, 3), (0, 1, 2, 3))])
    x = _solve(residual, np.concatenate([rvec, tvec, [aspect]])).x
    return float(x[6]), x[:3], x[3:6], project(K, x[:3], x[3:6], corners_of(x[6:]))


def _vanishing_point(segments: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Homogeneous least-squares intersection (3,) of the lines through the segments."""
    rows = []
    for p, q in segments:
        line = np.cross(np.append(p, 1.0), np.append(q, 1.0))
        rows.append(line / np.hypot(line[0], line[1]))
    # Conditioning: image coordinates are ~1e3, so scale them before the SVD.
    s = 1e-3
    L = np.array(rows) * np.array([1.0, 1.0, s])
    v = np.linalg.svd(L)[2][-1]
    point: np.ndarray = v * np.array([1 / s, 1 / s, 1.0])
    return point


def focal_from_vanishing_points(front: np.ndarray, side: np.ndarray, principal: np.ndarray,
                                 max_focal: float, side_face: str = "right") -> list[float]:
    """Focal lengths (px) from the box's three orthogonal vanishing points.

    For vanishing points v_i, v_j of orthogonal directions and principal point c,
    f^2 = -(v_i - c).(v_j - c). Pairs with a vanishing point (near) infinity, or giving no
    positive f^2 or one above `max_focal`, are skipped.

    Parameters
    ----------
    front, side : ndarray, shape (4, 2)
        TL, TR, BR, BL image (x, y) px of the front face and of the side face as photographed.
    principal : ndarray, shape (2,)
    max_focal : float
    side_face : {"right", "left", "top"}
        Where the side face lies (its edges then run along other world axes).

    Returns
    -------
    list of float
        Zero to three estimates, px.
    """
    x_edges = [(front[0], front[1]), (front[3], front[2])]
    y_edges = [(front[0], front[3]), (front[1], front[2])]
    if side_face == "top":  # the top's far edge runs along X, its left and right along Z
        x_edges.append((side[0], side[1]))
        z_edges = [(side[0], side[3]), (side[1], side[2])]
    else:  # a side's far edge runs along Y, its top and bottom along Z
        y_edges.append((side[1], side[2]) if side_face == "right" else (side[0], side[3]))
        z_edges = [(side[0], side[1]), (side[3], side[2])]
    vps = [_vanishing_point(x_edges), _vanishing_point(y_edges), _vanishing_point(z_edges)]
    out = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        vi, vj = vps[i], vps[j]
        if min(abs(vi[2]), abs(vj[2])) < 1e-12:
            continue
        f2 = -float((vi[:2] / vi[2] - principal) @ (vj[:2] / vj[2] - principal))
        if 0 < f2 < max_focal**2:
            out.append(float(np.sqrt(f2)))
    return out


def _box_starts(K: np.ndarray, front: FaceEvidence, side: FaceEvidence,
                side_face: str = "right") -> list[np.ndarray]:
    """Initial [rvec, tvec, W, D] from the front's homography and from the side's."""
    width, rvec, tvec = rectangle_pose(K, front.corners)
    depth, rvec_s, tvec_s = rectangle_pose(K, side.corners)
    second = SECOND_FACES[side_face]
    if second.v_is_depth:  # the side rectangle's aspect is W / D, its unit length D
        depth = width / depth if depth > 0 else float("nan")
    starts = [np.concatenate([rvec, tvec, [width, depth]])]
    R_s = cv2.Rodrigues(rvec_s)[0]
    R = R_s @ second.axes
    if side_face == "right":
        t = R_s[:, 2] * width + tvec_s
    else:  # X_cam = R_s A (X - o) / L + t_s in the rectangle's units L: scale to the height's
        unit = depth if second.v_is_depth else 1.0
        t = unit * tvec_s - R @ second.origin(width, depth)
    if np.isfinite(R).all() and np.isfinite(t).all():
        starts.append(np.concatenate([cv2.Rodrigues(R)[0].ravel(), t, [width, depth]]))
    return starts


def fit_box(K: np.ndarray, front: FaceEvidence, side: FaceEvidence, *,
            free_focal: bool = False, side_face: str = "right") -> BoxFit:
    """Width and depth (height = 1) and pose of a box whose front and second face share a photo.

    Model corners: P1 (0,0,0), P2 (W,0,0), P3 (W,1,0), P6 (0,1,0) (X right, Y down, Z into the
    object) and the second face's far corners: a right side P5 (W,0,D), P7 (W,1,D); a left
    side P5 (0,0,D), P7 (0,1,D); a top P5 (0,0,D), P7 (W,0,D). The edge the second face shares
    with the front is used once (the front's).

    Parameters
    ----------
    K : ndarray, shape (3, 3)
        Intrinsics; with `free_focal` only its principal point is used.
    front, side : FaceEvidence
        The side's quads TL, TR, BR, BL as photographed (a left side's TR is P1, a top's BL).
    free_focal : bool
        Fit the focal length too, started from the vanishing points' closed form and from a
        range of typical focal lengths.
    side_face : {"right", "left", "top"}

    Returns
    -------
    BoxFit
    """
    if side_face not in SECOND_FACES:
        raise ValueError(f"side_face must be right, left or top, got {side_face!r}")
    second = SECOND_FACES[side_face]
    box_corners = second.corners
    faces: FaceTerms = [(front, FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]
    n_lines = n_line_terms(faces)
    principal = K[:2, 2].astype(np.float64)
    best: OptimizeResult | None = None
    nfev = 0
    accept = _ACCEPT * _expected_cost(faces, n_lines)
    if free_focal:
        size = 2 * float(np.abs(np.concatenate([front.clicked, side.clicked]) - principal).max())
        size = max(size, 2 * float(principal.max()) + 1)
        lo, hi = (b * size for b in _FOCAL_BOUNDS)
        closed = focal_from_vanishing_points(front.corners, side.corners, principal, hi, side_face)
        residual, jac = residual_and_jacobian(lambda x: camera_matrix(float(np.exp(x[8])), principal),
                                              box_corners, 2, faces, log_focal=True)
        bounds = (np.r_[np.full(8, -np.inf), np.log(lo)], np.r_[np.full(8, np.inf), np.log(hi)])
        # The vanishing points' focal first; the spread of typical focal lengths only when that
        # start is missing or its fit is worse than the noise explains. Each start costs a full
        # solve (photo-like renders: 10-36 evaluations, 3-12 ms CPU), and on a consistent box the
        # closed form lands in the global minimum. Both poses (from the front and from the side)
        # are always tried: keeping the front's whenever the noise explains it moved a tracked
        # video frame's refined corners 4 px (tests/engine/video/test_video_tracking.py, seed 2).
        # The spread stops after the first focal length whose fit the noise explains, and once
        # the starts together have spent _NFEV_BUDGET: on points that are no box every start
        # slides towards the focal length's bound without converging, and sixteen took minutes.
        first = [float(np.median(closed))] if closed else []
        tried: set[float] = set()
        for guesses in (first, [*closed, *(m * size for m in _FOCAL_STARTS)]):
            if guesses is not first and best is not None and best.cost <= accept:
                break
            for f in guesses:
                if f in tried:  # one closed form is the first round's start already
                    continue
                tried.add(f)
                for x0 in _box_starts(camera_matrix(f, principal), front, side, side_face):
                    if not np.isfinite(x0).all() or nfev >= _NFEV_BUDGET:
                        continue
                    res = _solve(residual, np.r_[x0, np.log(np.clip(f, lo * 1.001, hi * 0.999))],
                                 bounds, jac)
                    nfev += int(res.nfev)
                    if best is None or res.cost < best.cost - 1e-9:
                        best = res
                if guesses is not first and best is not None and best.cost <= accept:
                    break
    else:
        residual, jac = residual_and_jacobian(lambda _: K, box_corners, 2, faces)
        for x0 in _box_starts(K, front, side, side_face):
            if not np.isfinite(x0).all():
                continue
            res = _solve(residual, x0, jac=jac)
            nfev += int(res.nfev)
            if best is None or res.cost < best.cost - 1e-9:
                best = res
    if best is None:
        raise ValueError("no finite start for the box fit")
    x = best.x
    focal = float(np.exp(x[8])) if free_focal else float(K[0, 0])
    Kx = camera_matrix(focal, principal) if free_focal else K
    pts = project(Kx, x[:3], x[3:6], box_corners(x[6:8]))
    cov = _covariance(best, n_lines)
    # (W, D, z, f) as functions of x: gradient by central differences (z is nonlinear in rvec).
    def shape(v: np.ndarray) -> np.ndarray:
        f = float(np.exp(v[8])) if free_focal else focal
        return np.array([v[6], v[7], centre_depth(v[:3], v[3:6], v[6]), f])

    G = np.zeros((4, x.size))
    for k in range(x.size):
        h = 1e-6 * max(1.0, abs(x[k]))
        e = np.zeros_like(x)
        e[k] = h
        G[:, k] = (shape(x + e) - shape(x - e)) / (2 * h)
    shape_cov = G @ cov @ G.T
    focal_std = float(np.sqrt(max(shape_cov[3, 3], 0.0))) if free_focal else None
    return BoxFit(float(x[6]), float(x[7]), x[:3].copy(), x[3:6].copy(), focal, focal_std,
                  pts[list(FRONT_IDX)], pts[list(second.idx)], shape_cov, _line_rms(best, n_lines),
                  G @ _influence(best), principal.copy(), nfev=nfev)

"""The joint least-squares problem: every view's edge lines and clicks (the single-view residuals
of `perspective`) with one shared box (width, depth; height 1), one focal length (fitted unless
given) and a pose per view; its start from each view's own fit, its solution, and the covariance
of the shape (the single-view sandwich over all views' residuals).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from prismcore.geometry.box_model import FRONT_IDX, SECOND_FACES, camera_matrix
from prismcore.geometry.evidence import undistort_evidence
from prismcore.geometry.lens import RadialDistortion
from prismcore.geometry.perspective import (
    F_SCALE,
    NOISE_CLICK_PX,
    NOISE_LINE_PX,
    SIGMA_CLICK_PX,
    SIGMA_LINE_PX,
    BoxFit,
    FaceEvidence,
    FaceTerms,
    cauchy_weights,
    fit_box,
    n_line_terms,
    residual_and_jacobian,
)
from prismcore.multiview.views import _Prepared
from prismcore.spec import KnownEdge

__all__: list[str] = []

_MAX_NFEV = 400


def _undistorted(view: _Prepared, face: FaceEvidence, lens: RadialDistortion) -> FaceEvidence:
    """`undistort_evidence` of one of the view's faces, once per face and lens: a fit makes a
    problem per solve (outliers, disagreements, model refits: 2N + 20 of them for N views), and
    undistorting every view's edge samples for each was 15 % of a 10-view fit."""
    key = (id(face), lens.kappa, lens.centre.tobytes())
    kept = view.undistorted.get(key)
    if kept is None or kept[0] is not face:  # the face is kept with it: its id names no other
        kept = view.undistorted[key] = (face, undistort_evidence(face, lens))
    return kept[1]


def _terms(view: _Prepared, lens: RadialDistortion) -> FaceTerms:
    front, side = view.front, view.side
    if lens.kappa != 0.0:
        front, side = _undistorted(view, front, lens), _undistorted(view, side, lens)
    second = SECOND_FACES[view.side_face]
    return [(front, FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]


class _Problem:
    """The joint least-squares problem over some views.

    x = (W, D[, log focal]) then per view (rvec, tvec): whitened residuals per view, its line terms
    then its click terms (as `perspective.residual_and_jacobian` lays them out). Each view's residuals and
    their Jacobian are `perspective.residual_and_jacobian`'s (closed form: the forward differences it
    replaces took nine residual evaluations per view and step, half of a 10-view fit's time).
    """

    def __init__(self, views: list[_Prepared], lens: RadialDistortion, principal: np.ndarray,
                 focal_px: float | None, offsets: dict[int, np.ndarray] | None = None) -> None:
        self.views = views
        self.principal = principal
        self.offsets = [None if offsets is None else offsets.get(v.index) for v in views]
        self.free_focal = focal_px is None
        self.n_shared = 3 if self.free_focal else 2
        self.terms = [_terms(v, lens) for v in views]
        fixed = camera_matrix(focal_px or 1.0, principal)

        def intrinsics(x: np.ndarray) -> np.ndarray:
            return camera_matrix(float(np.exp(x[8])), principal) if self.free_focal else fixed

        pairs = [residual_and_jacobian(intrinsics, SECOND_FACES[v.side_face].corners, 2, t,
                                       log_focal=self.free_focal)
                 for v, t in zip(views, self.terms, strict=True)]
        self.fns: list[Callable[[np.ndarray], np.ndarray]] = [fn for fn, _ in pairs]
        self.jacs: list[Callable[[np.ndarray], np.ndarray]] = [jac for _, jac in pairs]
        self.n_lines = [n_line_terms(t) for t in self.terms]
        self.sizes = [n + 8 * len(t) for n, t in zip(self.n_lines, self.terms, strict=True)]  # lines, clicks
        # Each view's residuals reweighted from the solver's sigmas to the view's own measured
        # noise (`_measured_noise`; 1 until measured).
        self.weights: list[np.ndarray] = []
        # Each view's residuals' sigma in px (lines, then clicks), made once: the whitening
        # every residual call undoes and redoes.
        self.units: list[np.ndarray] = []
        for v, n, size in zip(views, self.n_lines, self.sizes, strict=True):
            w = np.full(size, SIGMA_CLICK_PX / v.click_sigma_px)
            w[:n] = SIGMA_LINE_PX / v.line_sigma_px
            self.weights.append(w)
            unit = np.full(size, SIGMA_CLICK_PX)
            unit[:n] = SIGMA_LINE_PX
            self.units.append(unit)
        self.focal_px = focal_px

    def view_x(self, x: np.ndarray, v: int) -> np.ndarray:
        pose = x[self.n_shared + 6 * v: self.n_shared + 6 * v + 6]
        log_f = x[2] if self.free_focal else 0.0
        packed: np.ndarray = np.r_[pose, x[:2], log_f]
        return packed

    def residual(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([self.view_residual(x, v) for v in range(len(self.fns))])

    def view_residual(self, x: np.ndarray, v: int) -> np.ndarray:
        """View v's residuals as the solver sees them (whitened by the view's noise)."""
        whitened: np.ndarray = self.view_px(x, v) * self.weights[v] / self.units[v]
        return whitened

    def view_px(self, x: np.ndarray, v: int) -> np.ndarray:
        """View v's residuals in px: line end points' distances, then click offsets."""
        r: np.ndarray = self.fns[v](self.view_x(x, v))
        offset = self.offsets[v]
        px: np.ndarray = (r if offset is None else r - offset) * self.units[v]
        return px

    def focal(self, x: np.ndarray) -> float:
        return float(np.exp(x[2])) if self.free_focal else float(self.focal_px or 0.0)

    def box_fit(self, x: np.ndarray, v: int) -> BoxFit:
        """View v at x as a single-view BoxFit (for `perspective`'s rounding patterns: no
        covariance; its influence only sizes the residuals)."""
        pose = x[self.n_shared + 6 * v: self.n_shared + 6 * v + 6]
        empty = np.zeros((4, 2))
        return BoxFit(float(x[0]), float(x[1]), pose[:3].copy(), pose[3:].copy(), self.focal(x), None,
                      empty, empty, np.zeros((4, 4)), 0.0, np.zeros((4, self.sizes[v])), self.principal)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Each view's block from its own residuals alone (the offsets are constants): its
        closed-form Jacobian in (rvec, tvec, W, D, log focal) spread to the shared and its pose
        columns."""
        J = np.zeros((sum(self.sizes), x.size))
        row, ns = 0, self.n_shared
        for v, jac in enumerate(self.jacs):
            block = jac(self.view_x(x, v)) * self.weights[v][:, None]
            J[row:row + block.shape[0], :ns] = block[:, 6:6 + ns]
            J[row:row + block.shape[0], ns + 6 * v: ns + 6 * v + 6] = block[:, :6]
            row += block.shape[0]
        return J

    def noise(self) -> np.ndarray:
        """Per residual, the assumed data noise over the sigma it is whitened by, squared."""
        parts = []
        for n_lines, size, w in zip(self.n_lines, self.sizes, self.weights, strict=True):
            part = np.full(size, (NOISE_CLICK_PX / SIGMA_CLICK_PX) ** 2)
            part[:n_lines] = (NOISE_LINE_PX / SIGMA_LINE_PX) ** 2
            parts.append(part * w**2)
        return np.concatenate(parts)

    def solve(self, x0: np.ndarray) -> OptimizeResult:
        return least_squares(self.residual, x0, jac=self.jacobian, method="trf", x_scale="jac",
                             loss="cauchy", f_scale=F_SCALE, max_nfev=_MAX_NFEV)

    def chi_square(self, res: OptimizeResult) -> float:
        """The robust cost in units of the assumed noise (chi-square-like)."""
        rho = F_SCALE**2 * np.log1p((res.fun / F_SCALE) ** 2)
        return float(np.sum(rho / self.noise()))

    def blocks(self, fun: np.ndarray) -> list[np.ndarray]:
        return np.split(fun, np.cumsum(self.sizes)[:-1])


def _start(views: list[_Prepared], lens: RadialDistortion, principal: np.ndarray,
           focal: float, free: bool) -> np.ndarray:
    """Each view's own box fitted at the shared start focal: its pose, and the median shape."""
    K = camera_matrix(focal, principal)
    poses, shapes = [], []
    for v in views:
        terms = _terms(v, lens)
        fit = fit_box(K, terms[0][0], terms[1][0], side_face=v.side_face)
        poses.append(np.r_[fit.rvec, fit.tvec])
        shapes.append((fit.width, fit.depth))
    W, D = np.median(np.array(shapes), axis=0)
    shared = [W, D, math.log(focal)] if free else [W, D]
    return np.concatenate([np.array(shared, dtype=np.float64), *poses])


def _dims(scale: KnownEdge, shape: np.ndarray) -> np.ndarray:
    W, D = float(shape[0]), float(shape[1])
    k = scale.length_mm / {"width": W, "height": 1.0, "depth": D}[scale.edge]
    return np.array([W * k, k, D * k])


def _dims_gradient(scale: KnownEdge, x: np.ndarray) -> np.ndarray:
    """d(width, height, depth) / d(W, D), (3, 2), by central differences."""
    G = np.zeros((3, 2))
    for c in range(2):
        h = 1e-6 * max(1.0, abs(x[c]))
        e = np.zeros(2)
        e[c] = h
        G[:, c] = (_dims(scale, x[:2] + e) - _dims(scale, x[:2] - e)) / (2 * h)
    return G


def _covariance(problem: _Problem, res: OptimizeResult) -> np.ndarray:
    """The single-view sandwich (`perspective._covariance`) over all views' residuals."""
    J = np.asarray(res.jac, dtype=np.float64)
    w = cauchy_weights(res.fun)
    noise = problem.noise()
    Jw = J * w[:, None]
    A_inv = np.linalg.pinv(J.T @ Jw, rcond=1e-12)
    cov: np.ndarray = A_inv @ (Jw.T @ (Jw * noise[:, None])) @ A_inv
    dof = float(w.sum()) - res.x.size
    factor = max(1.0, float(np.sum(w * res.fun**2 / noise)) / dof) if dof >= 1.0 else 1.0
    return cov * factor


def _dims_sigma(scale: KnownEdge, x: np.ndarray, cov: np.ndarray) -> np.ndarray:
    G = _dims_gradient(scale, x)
    sigma: np.ndarray = np.sqrt(np.clip(np.diag(G @ cov[:2, :2] @ G.T), 0.0, None))
    return sigma


def _fit(views: list[_Prepared], lens: RadialDistortion, principal: np.ndarray, focal_px: float | None,
         x0: np.ndarray | None = None, offsets: dict[int, np.ndarray] | None = None
         ) -> tuple[_Problem, OptimizeResult]:
    free = focal_px is None
    problem = _Problem(views, lens, principal, focal_px, offsets)
    if x0 is None:
        focals = [v.focal_px for v in views if v.focal_px is not None]
        start_f = focal_px if focal_px is not None else float(np.median(focals)) if focals else \
            float(2 * principal.max() + 1)
        x0 = _start(views, lens, principal, start_f, free)
    return problem, problem.solve(x0)


def _without(x: np.ndarray, n_shared: int, v: int) -> np.ndarray:
    return np.delete(x, np.arange(n_shared + 6 * v, n_shared + 6 * v + 6))


def _only(x: np.ndarray, n_shared: int, v: int) -> np.ndarray:
    kept: np.ndarray = np.r_[x[:n_shared], x[n_shared + 6 * v: n_shared + 6 * v + 6]]
    return kept

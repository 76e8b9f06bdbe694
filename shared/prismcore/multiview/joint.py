"""Several photos of one part (or frames of one video) measured as ONE box.

Each view is first measured alone (`pipeline.plan_scan`: its points checked, its edges refined to
sub-pixel lines, its own box fitted). The joint fit then shares what one camera and one part
share: one focal length (fitted unless given), one radial lens distortion (read from every view's
edges together, `lens.estimate_distortion`), one width and depth (height 1, the known edge
sets the millimetres); each view keeps its own pose. All views' edge lines and clicks are fitted
in one least-squares problem with the single-view residuals (`perspective`: each model edge's end
points on its fitted line, sigma 0.3 px, each corner weakly towards its click, sigma 5 px, a
robust Cauchy loss), started from each view's own fit (on request, a view's edge lines that its
clicks disagree with are left out: `edge_agree_px`). Each view is then weighed by the noise its
own residuals show (its lines' robust scale, its clicks' RMS: `_measured_noise`), and an edge line
whose model edge ends farther than LINE_REJECT_PX from it at the joint solution is left out, the
worst first with a refit after each (`_reject_lines`): a line on a printed border, a seam or a
shadow must then disagree with the box every view shares, not with one view's clicks. The edges'
rounding is read
from every view's shading through the shared box and taken out as one view's fit takes it out.
The covariance is the single-view sandwich over all views' residuals, scaled by their variance
factor (never down), plus what the model takes as known: the lens distortion and the edge radius
(refits at +-1 sigma of each) and where each rounded fold was found on its shading ramp (one
physical fold alike in every view).

A view that disagrees with the others beyond its noise is named and left out, not averaged in:
with three views or more, each view's disagreement is the cost it adds by having to share the
box, T = S(all) - S(the others) - S(it alone), chi-square on the shared parameters under the
assumed noise (scaled by the separate fits' variance factor, never down); the worst view past
the 99.9 % point is left out and the test repeated. With two views the one that is wrong cannot
be told: their disagreement is a warning. A view whose single-view fit refuses (a point the
fitted box sits far from) is left out with that reason.

All views must be of one camera (one image size; the principal point is the image centre) and
mark the same front face, P1 the same corner; each view's second face may be its right, left or
top face (`ScanSpec.side_face`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from scipy.optimize import OptimizeResult, least_squares
from scipy.stats import chi2

from prismcore.errors import InputError
from prismcore.geometry.faces import clicked_quads
from prismcore.geometry.lens import RadialDistortion, estimate_distortion
from prismcore.geometry.model_error import (
    FOLD_FRACTION,
    ROUNDING_RMS_MM,
    _rows,
    edge_shifts,
    rounding_shifts,
)
from prismcore.geometry.perspective import (
    _F_SCALE,
    _FRONT_IDX,
    _SECOND,
    NOISE_CLICK_PX,
    NOISE_LINE_PX,
    SIGMA_CLICK_PX,
    SIGMA_LINE_PX,
    BoxFit,
    FaceEvidence,
    FaceTerms,
    _camera,
    _n_line_terms,
    _residual_fn,
    box_edge_samples,
    fit_box,
    project,
    undistort_evidence,
)
from prismcore.geometry.rounding import STD_FLOOR_MM, RadiusEstimate, estimate_edge_radius
from prismcore.scan.measure import Dimensions
from prismcore.spec import KnownEdge, ReferencePoints, ScanSpec

__all__ = ["CLICK_WARN_PX", "OUTLIER_LEVEL", "JointResult", "LeftOut", "View", "ViewFit", "fit_views"]

OUTLIER_LEVEL = 0.999
"""A view is left out when its disagreement with the others passes this chi-square quantile."""
_MAX_NFEV = 400
CLICK_WARN_PX = 5.0
"""A view whose clicks lie farther than this (RMS, px) from the box all views share is warned
about: its points (or the edges that hold its pose) may be wrong. Photo-like renders with clicks
off by up to 3 px reach 2.9 px at most (60 views); the real video's frame 105, marked 5.9 px off
its true box, 8.7 px."""
LINE_REJECT_PX = 3 * NOISE_LINE_PX
"""A refined edge line is left out of the joint fit when an end of its model edge lies farther than
this (px) from it at the joint solution: three times the assumed noise of a line at a corner. Such
a line is not the box's edge as the model sees it (a printed border, a seam, a shadow, a fold's
ramp read at the wrong place); measured on the renders against their true box, lines that far off
are those, and the Cauchy loss alone lets them pull hardest (its influence peaks at 0.9 px)."""
MIN_CLICK_SIGMA_PX = 1.0
"""The least per-axis noise a view's clicks are weighed by, px, however close they fit."""
_MAX_REJECTED = 40  # a bound on the refits; the real video's twelve frames leave out about 18 lines
_DIMENSIONS = ("width", "height", "depth")


@dataclass(frozen=True)
class View:
    """One photo of the part and the seven points clicked on it.

    image : ndarray, shape (H, W, 3)
        RGB, uint8 (or float32 0-255).
    points : ReferencePoints or sequence of seven (x, y)
        P1..P7 in the engine's order, image px.
    side_face : {"auto", "right", "left", "top"}
        Which face P4, P5, P7 mark (as `ScanSpec.side_face`).
    name : str
        How the view is named in the result (a file name, "frame 127"); "view k" when empty.
    """

    image: np.ndarray
    points: ReferencePoints | Sequence[Sequence[float]]
    side_face: str = "auto"
    name: str = ""


@dataclass(frozen=True)
class ViewFit:
    """One view in the joint fit.

    name : str
    rvec, tvec : ndarray, shape (3,)
        World-to-camera pose (Rodrigues; translation in units of the box's height).
    click_rms_px, line_rms_px : float
        RMS distance (px) of the shared box's corners from this view's clicks, and of its edges'
        end points from this view's fitted edge lines (0 when none was fitted).
    single : Dimensions
        What the view measures alone (`plan_scan`).
    disagreement : float or None
        Its chi-square T against the others (None with fewer than three views).
    lines_left_out : int
        Its refined edge lines left out for lying more than LINE_REJECT_PX from the joint box.
    """

    name: str
    rvec: np.ndarray
    tvec: np.ndarray
    click_rms_px: float
    line_rms_px: float
    single: Dimensions
    disagreement: float | None = None
    lines_left_out: int = 0


@dataclass(frozen=True)
class LeftOut:
    """A view the joint fit does not use, and why (in words, with its figures)."""

    name: str
    index: int
    reason: str


@dataclass(frozen=True)
class JointResult:
    """The box several views measure together.

    dimensions : Dimensions
        Width, height, depth (mm) and their 1-sigma `uncertainty`.
    focal_px : float
    focal_std_px : float or None
        1-sigma of a fitted focal length; None when it was given.
    distortion : RadialDistortion
        The lens distortion removed from every view (shared), with its 1-sigma.
    views : tuple of ViewFit
        The views used, in input order.
    left_out : tuple of LeftOut
    warnings : tuple of str
    nfev : int
        Residual evaluations of the joint solves (the work, independent of the machine's load).
    lines_left_out : int
        Refined edge lines left out because they lie more than LINE_REJECT_PX from the joint box.
    """

    dimensions: Dimensions
    focal_px: float
    focal_std_px: float | None
    distortion: RadialDistortion
    views: tuple[ViewFit, ...]
    left_out: tuple[LeftOut, ...]
    warnings: tuple[str, ...] = field(default=())
    nfev: int = 0
    lines_left_out: int = 0


@dataclass(frozen=True)
class _Prepared:
    """A view measured alone, its evidence ready for the joint fit (distortion not yet removed)."""

    index: int
    name: str
    side_face: str
    front: FaceEvidence
    side: FaceEvidence
    single: Dimensions
    focal_px: float | None
    image: np.ndarray
    edges_dropped: int = 0
    lines_rejected: int = 0
    line_sigma_px: float = SIGMA_LINE_PX
    click_sigma_px: float = SIGMA_CLICK_PX

    def without_lines(self, drop: dict[str, set[int]] | None = None) -> _Prepared:
        """The view with the named sides' edge lines (all, when None) taken out (its clicks stay)."""
        faces = []
        for name in ("front", "side"):
            face: FaceEvidence = getattr(self, name)
            gone = set(range(4)) if drop is None else drop.get(name, set())
            lines = tuple(None if s in gone else line for s, line in enumerate(face.lines))
            samples = tuple(None if s in gone else e for s, e in enumerate(face.samples))
            faces.append(FaceEvidence(face.corners, face.clicked, lines, samples))
        n = 0 if drop is None else sum(len(v) for v in drop.values())
        return replace(self, front=faces[0], side=faces[1], edges_dropped=self.edges_dropped + n)


def _prepare(k: int, view: View, scale: KnownEdge, focal_px: float | None,
             edge_agree_px: float | None = None) -> _Prepared:
    from prismcore.scan.pipeline import plan_scan

    name = view.name or f"view {k + 1}"
    points = view.points if isinstance(view.points, ReferencePoints) else [list(map(float, p))
                                                                           for p in view.points]
    spec = ScanSpec.model_validate({"image": name if "." in name else f"{name}.png", "points": points,
                                    "side_face": view.side_face, "scale": scale, "focal_px": focal_px})
    plan = plan_scan(spec, view.image)
    if not plan.dimensions.perspective:
        raise InputError(f"{name}: the box was not fitted in perspective (all seven points are needed)")
    assert spec.points is not None
    face = plan.side_face
    marked = clicked_quads(spec.points, two_photo=False, side_face=face)
    evidence = [FaceEvidence(plan.faces[i].region, getattr(marked, n),
                             tuple(f.line if f.fitted else None for f in plan.edges[n]),
                             tuple(f.points if f.fitted else None for f in plan.edges[n]))
                for i, n in enumerate(("front", "side"))]
    fitted = plan.camera.get("focal_px")
    prepared = _Prepared(k, name, face, evidence[0], evidence[1], plan.dimensions,
                         float(fitted) if fitted is not None else None, view.image)
    return prepared if edge_agree_px is None else _agreeing(prepared, edge_agree_px)


def _agreeing(view: _Prepared, limit_px: float) -> _Prepared:
    """The view without the refined edge lines its clicks disagree with: a side's line is dropped
    when the two clicked corners at its ends lie farther than `limit_px` from it (mean distance)."""
    drop: dict[str, set[int]] = {}
    for name, sides in (("front", (0, 1, 2, 3)), ("side", _SECOND[view.side_face].sides)):
        face: FaceEvidence = getattr(view, name)
        for s in sides:
            line = face.lines[s]
            if line is None:
                continue
            ends = face.clicked[[s, (s + 1) % 4]]
            if float(np.abs(ends @ line[:2] + line[2]).mean()) > limit_px:
                drop.setdefault(name, set()).add(s)
    return view.without_lines(drop) if drop else view


def _terms(view: _Prepared, lens: RadialDistortion) -> FaceTerms:
    front, side = view.front, view.side
    if lens.kappa != 0.0:
        front, side = undistort_evidence(front, lens), undistort_evidence(side, lens)
    second = _SECOND[view.side_face]
    return [(front, _FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]


class _Problem:
    """The joint least-squares problem over some views.

    x = (W, D[, log focal]) then per view (rvec, tvec): whitened residuals per view, its line terms
    then its click terms (as `perspective._residual_fn` lays them out).
    """

    def __init__(self, views: list[_Prepared], lens: RadialDistortion, principal: np.ndarray,
                 focal_px: float | None, offsets: dict[int, np.ndarray] | None = None) -> None:
        self.views = views
        self.principal = principal
        self.offsets = [None if offsets is None else offsets.get(v.index) for v in views]
        self.free_focal = focal_px is None
        self.n_shared = 3 if self.free_focal else 2
        self.terms = [_terms(v, lens) for v in views]
        fixed = _camera(focal_px or 1.0, principal)

        def intrinsics(x: np.ndarray) -> np.ndarray:
            return _camera(float(np.exp(x[8])), principal) if self.free_focal else fixed

        self.fns: list[Callable[[np.ndarray], np.ndarray]] = [
            _residual_fn(intrinsics, _SECOND[v.side_face].corners, 2, t)
            for v, t in zip(views, self.terms, strict=True)]
        self.n_lines = [_n_line_terms(t) for t in self.terms]
        self.sizes = [n + 8 * len(t) for n, t in zip(self.n_lines, self.terms, strict=True)]  # lines, clicks
        # Each view's residuals reweighted from the solver's sigmas to the view's own measured
        # noise (`_measured_noise`; 1 until measured).
        self.weights: list[np.ndarray] = []
        for v, n, size in zip(views, self.n_lines, self.sizes, strict=True):
            w = np.full(size, SIGMA_CLICK_PX / v.click_sigma_px)
            w[:n] = SIGMA_LINE_PX / v.line_sigma_px
            self.weights.append(w)
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
        whitened: np.ndarray = self.view_px(x, v) * self.weights[v] / self._unit(v)
        return whitened

    def view_px(self, x: np.ndarray, v: int) -> np.ndarray:
        """View v's residuals in px: line end points' distances, then click offsets."""
        r: np.ndarray = self.fns[v](self.view_x(x, v))
        offset = self.offsets[v]
        px: np.ndarray = (r if offset is None else r - offset) * self._unit(v)
        return px

    def _unit(self, v: int) -> np.ndarray:
        unit = np.full(self.sizes[v], SIGMA_CLICK_PX)
        unit[:self.n_lines[v]] = SIGMA_LINE_PX
        return unit

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
        """Forward differences, each view's block from its own residuals alone."""
        J = np.zeros((sum(self.sizes), x.size))
        row = 0
        for v, fn in enumerate(self.fns):
            base = fn(self.view_x(x, v))  # the offsets are constants: they cancel
            cols = [*range(self.n_shared), *range(self.n_shared + 6 * v, self.n_shared + 6 * v + 6)]
            for c in cols:
                h = 1.49e-8 * max(1.0, abs(x[c]))
                step = x.copy()
                step[c] += h
                J[row:row + base.size, c] = (fn(self.view_x(step, v)) - base) / h * self.weights[v]
            row += base.size
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
                             loss="cauchy", f_scale=_F_SCALE, max_nfev=_MAX_NFEV)

    def chi_square(self, res: OptimizeResult) -> float:
        """The robust cost in units of the assumed noise (chi-square-like)."""
        rho = _F_SCALE**2 * np.log1p((res.fun / _F_SCALE) ** 2)
        return float(np.sum(rho / self.noise()))

    def blocks(self, fun: np.ndarray) -> list[np.ndarray]:
        return np.split(fun, np.cumsum(self.sizes)[:-1])


def _start(views: list[_Prepared], lens: RadialDistortion, principal: np.ndarray,
           focal: float, free: bool) -> np.ndarray:
    """Each view's own box fitted at the shared start focal: its pose, and the median shape."""
    K = _camera(focal, principal)
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


def _covariance(problem: _Problem, res: OptimizeResult) -> np.ndarray:
    """The single-view sandwich (`perspective._covariance`) over all views' residuals."""
    J = np.asarray(res.jac, dtype=np.float64)
    w = 1.0 / (1.0 + (res.fun / _F_SCALE) ** 2)
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


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else 0.0


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


@dataclass(frozen=True)
class _Rounding:
    """The box's edge radius (mm), shared by every view, and each view's fold offsets.

    read : whether the photos' shading gave the radius (else none is corrected and
        ROUNDING_RMS_MM is only an uncertainty)
    folds : per view index, the folds' (midpoint mm, image offset px) (`RadiusEstimate`)
    """

    radius_mm: float
    std_mm: float
    read: bool
    folds: dict[int, tuple[tuple[np.ndarray, np.ndarray], ...]]


def _mm_per_unit(scale: KnownEdge, x: np.ndarray) -> float:
    return float(_dims(scale, x[:2])[1])  # the height is the model's unit


def _read_rounding(problem: _Problem, x: np.ndarray, lens: RadialDistortion, k: float) -> _Rounding:
    """Each view's edge radius read from its shading through the shared box (`rounding`), pooled
    with inverse-variance weights (at least STD_FLOOR_MM)."""
    estimates: dict[int, RadiusEstimate] = {}
    K = _camera(problem.focal(x), problem.principal)
    size = np.array([x[0], 1.0, x[1]]) * k
    for v, view in enumerate(problem.views):
        fit = problem.box_fit(x, v)
        R = cv2.Rodrigues(np.asarray(fit.rvec, dtype=np.float64))[0]

        def to_image(world_mm: np.ndarray, fit: BoxFit = fit) -> np.ndarray:
            return lens.distort(project(K, fit.rvec, fit.tvec, world_mm / k))

        found = estimate_edge_radius(view.image, to_image, size, -R.T @ fit.tvec * k)
        if found is not None:
            estimates[view.index] = found
    if not estimates:
        return _Rounding(0.0, ROUNDING_RMS_MM, False, {})
    weights = np.array([1.0 / e.std_mm**2 for e in estimates.values()])
    radius = float(weights @ np.array([e.radius_mm for e in estimates.values()]) / weights.sum())
    std = max(STD_FLOOR_MM, float(1.0 / np.sqrt(weights.sum())))
    return _Rounding(radius, std, True, {i: e.fold_offsets for i, e in estimates.items()})


def _offsets(problem: _Problem, x: np.ndarray, rounding: _Rounding, radius_mm: float, k: float
             ) -> dict[int, np.ndarray]:
    """Per view index, how the rounded edges move its whitened residuals at x (silhouettes inside
    the sharp outline by the inset `radius_mm` implies; folds where the shading put the sharp edge),
    as `measure.measure_box` takes them out of a single view's fit."""
    out = {}
    for v, view in enumerate(problem.views):
        fit = problem.box_fit(x, v)
        front, side = problem.terms[v][0][0], problem.terms[v][1][0]
        moved = np.zeros(problem.sizes[v])
        if radius_mm > 0:
            moved += rounding_shifts(fit, front, side, radius_mm / k, side_face=view.side_face)[0]
        folds = rounding.folds.get(view.index, ())
        if folds:
            moved += edge_shifts(fit, front, side, [(mid / k, -offset) for mid, offset in folds],
                                 side_face=view.side_face)
        out[view.index] = moved
    return out


def _measured_noise(prepared: list[_Prepared], problem: _Problem, x: np.ndarray) -> list[_Prepared]:
    """Each view with the noise its own residuals at x show: its edge lines' robust scale (1.4826
    times the median end point distance, px, at least SIGMA_LINE_PX) and its clicks' RMS offset
    (px per axis, at least MIN_CLICK_SIGMA_PX).

    The solver's fixed sigmas (0.3 px a line, 5 px a click) let a view's lines decide its pose
    however far its clicks then lie: on the real video a frame whose lines include a printed
    border keeps them with its clicks 8 px off. Weighed by what each view shows (variance
    components, one per view and kind), a view whose lines and clicks disagree says less, and
    clicks as good as the renders' (0-3 px) are no longer ten times under-weighted.
    """
    out = []
    for v, view in enumerate(prepared):
        r = problem.view_px(x, v)
        n = problem.n_lines[v]
        line = max(SIGMA_LINE_PX, 1.4826 * float(np.median(np.abs(r[:n])))) if n else SIGMA_LINE_PX
        click = max(MIN_CLICK_SIGMA_PX, float(np.sqrt(np.mean(r[n:] ** 2))))
        out.append(replace(view, line_sigma_px=line, click_sigma_px=click))
    return out


def _worst_line(problem: _Problem, x: np.ndarray) -> tuple[int, str, int, float] | None:
    """The edge line farthest from the box at x: (view, "front" or "side", side, px), the distance
    that of the farther of its model edge's end points (after the rounding offsets); None when no
    view has a line."""
    worst: tuple[int, str, int, float] | None = None
    for v in range(len(problem.views)):
        n = problem.n_lines[v]
        ends = np.abs(problem.view_px(x, v)[:n]).reshape(-1, 2).max(axis=1)
        if ends.size and (worst is None or float(ends.max()) > worst[3]):
            k = int(np.argmax(ends))
            face, side, _, _ = _rows(problem.terms[v])[2 * k]
            worst = (v, "front" if face == 0 else "side", side, float(ends[k]))
    return worst


def _reject_lines(prepared: list[_Prepared], problem: _Problem, res: OptimizeResult, lens: RadialDistortion,
                  focal_px: float | None, scale: KnownEdge, rounding: _Rounding | None,
                  offsets: dict[int, np.ndarray]
                  ) -> tuple[list[_Prepared], _Problem, OptimizeResult, dict[int, np.ndarray], int]:
    """Leave out, one at a time and refitting after each, the edge line farthest from the joint
    box while it lies more than LINE_REJECT_PX from it.

    Judged against the box all views share, not against the view's own clicks: a wrong line
    (a printed border, a seam, one end on a shadow) has to disagree with the other views' edges
    too, while a silhouette rightly inside its clicked corners (a rounded edge) is kept. The worst
    first, because one wrong line drags the box and so the residuals of the right ones near it.
    The rounding offsets (when read) are recomputed for each new set of lines.

    Returns the views, the problem and its solution, the offsets, and the work (nfev).
    """
    nfev = 0
    for _ in range(_MAX_REJECTED):
        worst = _worst_line(problem, res.x)
        if worst is None or worst[3] <= LINE_REJECT_PX:
            break
        v, face, side, _ = worst
        prepared = list(prepared)
        view = prepared[v].without_lines({face: {side}})
        prepared[v] = replace(view, edges_dropped=prepared[v].edges_dropped,
                              lines_rejected=prepared[v].lines_rejected + 1)
        if rounding is not None and rounding.read:
            bare = _Problem(prepared, lens, problem.principal, focal_px)
            offsets = _offsets(bare, res.x, rounding, rounding.radius_mm, _mm_per_unit(scale, res.x))
        problem, res = _fit(prepared, lens, problem.principal, focal_px, res.x, offsets)
        nfev += int(res.nfev)
    return prepared, problem, res, offsets, nfev


def _disagreements(problem: _Problem, res: OptimizeResult, lens: RadialDistortion, focal_px: float | None,
                   offsets: dict[int, np.ndarray]) -> tuple[np.ndarray, float, int]:
    """Per view T = S(all) - S(others) - S(alone), the limit T must stay under, and the work."""
    views, principal = problem.views, problem.principal
    total = problem.chi_square(res)
    n_shared = problem.n_shared
    T, scales, nfev = [], [], 0
    for v in range(len(views)):
        others = [u for i, u in enumerate(views) if i != v]
        p_o, r_o = _fit(others, lens, principal, focal_px, _without(res.x, n_shared, v), offsets)
        p_a, r_a = _fit([views[v]], lens, principal, focal_px, _only(res.x, n_shared, v), offsets)
        nfev += int(r_o.nfev) + int(r_a.nfev)
        separate = p_o.chi_square(r_o) + p_a.chi_square(r_a)
        dof = res.fun.size - (r_o.x.size + r_a.x.size)
        T.append(max(0.0, total - separate))
        scales.append(max(1.0, separate / dof) if dof > 0 else 1.0)
    # The separate fits say how noisy these clicks and edges really are: the median over views of
    # that factor (one bad view inflates only the fits that keep it).
    limit = float(chi2.ppf(OUTLIER_LEVEL, n_shared)) * float(np.median(scales))
    return np.array(T), limit, nfev


def _refit_spread(problem: _Problem, x: np.ndarray, scale: KnownEdge, focal_px: float | None,
                  variants: list[tuple[RadialDistortion, dict[int, np.ndarray]]]) -> tuple[np.ndarray, int]:
    """How far the dimensions move when refitted under each variant (lens, offsets) of the model:
    the largest move per dimension, and the work."""
    base = _dims(scale, x[:2])
    moves, nfev = [np.zeros(3)], 0
    for lens, offsets in variants:
        _, res = _fit(problem.views, lens, problem.principal, focal_px, x, offsets)
        nfev += int(res.nfev)
        moves.append(np.abs(_dims(scale, res.x[:2]) - base))
    spread: np.ndarray = np.max(np.array(moves), axis=0)
    return spread, nfev


def _model_sigma(problem: _Problem, x: np.ndarray, scale: KnownEdge, focal_px: float | None,
                 lens: RadialDistortion, rounding: _Rounding, offsets: dict[int, np.ndarray]
                 ) -> tuple[np.ndarray, int]:
    """1-sigma (3,) of the dimensions from what the model takes as known: the lens distortion (refit
    at +-1 sigma of it) and the edge radius (refit at +-1 sigma of the radius read, or at the prior
    ROUNDING_RMS_MM when none was read). Each is the larger move of its refits."""
    k = _mm_per_unit(scale, x)
    nfev = 0
    lens_sigma = np.zeros(3)
    if lens.kappa_std > 0:
        variants = [(RadialDistortion(lens.kappa + s * lens.kappa_std, 0.0, lens.centre), offsets)
                    for s in (1.0, -1.0)]
        lens_sigma, work = _refit_spread(problem, x, scale, focal_px, variants)
        nfev += work
    radii = ([rounding.radius_mm + s * rounding.std_mm for s in (1.0, -1.0)] if rounding.read
             else [rounding.std_mm])
    variants = [(lens, _offsets(problem, x, rounding, max(r, 0.0), k)) for r in radii]
    round_sigma, work = _refit_spread(problem, x, scale, focal_px, variants)
    return np.hypot(lens_sigma, round_sigma), nfev + work


def _dims_gradient(scale: KnownEdge, x: np.ndarray) -> np.ndarray:
    """d(width, height, depth) / d(W, D), (3, 2), by central differences."""
    G = np.zeros((3, 2))
    for c in range(2):
        h = 1e-6 * max(1.0, abs(x[c]))
        e = np.zeros(2)
        e[c] = h
        G[:, c] = (_dims(scale, x[:2] + e) - _dims(scale, x[:2] - e)) / (2 * h)
    return G


def _fold_sigma(problem: _Problem, res: OptimizeResult, scale: KnownEdge, rounding: _Rounding) -> np.ndarray:
    """1-sigma (3,) of the dimensions from where the edge detector found each rounded fold (both
    faces seen): anywhere on the shading ramp, FOLD_FRACTION radii (of the radius read plus its
    sigma, or ROUNDING_RMS_MM), as `model_error.model_error_cov` takes it for one view. One
    physical fold is found alike in every view (the same surface and light), so its shifts in
    all views move together; different folds are independent. Carried to the shape by the joint
    fit's linear response (robust weights frozen)."""
    x = res.x
    k = _mm_per_unit(scale, x)
    radius = (rounding.radius_mm + rounding.std_mm) if rounding.read else ROUNDING_RMS_MM
    J = np.asarray(res.jac, dtype=np.float64)
    w = 1.0 / (1.0 + (res.fun / _F_SCALE) ** 2)
    Jw = J * w[:, None]
    influence = -np.linalg.pinv(J.T @ Jw, rcond=1e-12)[:2] @ Jw.T  # d(W, D) / d(residuals)
    starts = np.r_[0, np.cumsum(problem.sizes)[:-1]]
    by_edge: dict[tuple[int, int], np.ndarray] = {}
    for v, view in enumerate(problem.views):
        terms = problem.terms[v]
        rows = _rows(terms)
        patterns = rounding_shifts(problem.box_fit(x, v), terms[0][0], terms[1][0],
                                   FOLD_FRACTION * radius / k, side_face=view.side_face)[1]
        for pattern in patterns:
            hit = np.flatnonzero(pattern)
            if hit.size == 0:
                continue
            key = (rows[int(hit[0])][0], rows[int(hit[0])][1])
            full = by_edge.setdefault(key, np.zeros(res.fun.size))
            full[starts[v]: starts[v] + pattern.size] += pattern * problem.weights[v]
    G = _dims_gradient(scale, x)
    var = np.zeros(3)
    for full in by_edge.values():
        var += (G @ (influence @ full)) ** 2
    sigma: np.ndarray = np.sqrt(var)
    return sigma


def fit_views(views: Sequence[View], scale: KnownEdge, *, focal_px: float | None = None,
              edge_agree_px: float | None = None) -> JointResult:
    """Measure several views of one box as one box.

    Parameters
    ----------
    views : sequence of View
        Photos of one part by one camera (same image size), each with its seven points on the
        same front face.
    scale : KnownEdge
        One true edge length of the part (mm): it sets the millimetres of every dimension.
    focal_px : float, optional
        The camera's focal length, px; fitted from all views together when not given.
    edge_agree_px : float, optional
        Use a refined edge line only when the clicked corners at its ends lie this close to it
        (mean distance, px); all are used when None (the default). A guard against edges taken
        from printed borders or seams, at a cost on rounded edges, whose silhouettes lie inside
        the clicked corners: see benchmarks/joint_fit.py (--edge-agree-px) for both sides.

    Returns
    -------
    JointResult
        The dimensions (mm) with their 1-sigma, the shared camera, each view's pose and residual
        RMS, and the views left out with the reason.

    Raises
    ------
    InputError
        For no views, views of different sizes, a scale that is no known edge, or when no view
        can be measured (each view's reason is given).
    """
    if not views:
        raise InputError("no views to measure")
    if not isinstance(scale, KnownEdge):
        raise InputError("a joint fit needs one known edge as its scale (kind 'edge')")
    sizes = {v.image.shape[:2] for v in views}
    if len(sizes) != 1:
        listed = ", ".join(f"{w}x{h}" for h, w in sorted(sizes))
        raise InputError(f"the views must come from one camera at one image size, got {listed}")
    h, w = views[0].image.shape[:2]
    principal = np.array([(w - 1) / 2, (h - 1) / 2])
    prepared: list[_Prepared] = []
    left_out: list[LeftOut] = []
    for k, view in enumerate(views):
        try:
            prepared.append(_prepare(k, view, scale, focal_px, edge_agree_px))
        except InputError as exc:
            name = view.name or f"view {k + 1}"
            left_out.append(LeftOut(name, k, f"measured alone it is refused: {exc}"))
    if not prepared:
        raise InputError("no view could be measured: " + "; ".join(f"{o.name}: {o.reason}" for o in left_out))
    radius = float(np.hypot(*(principal + 0.5)))
    samples = [s for v in prepared for s in box_edge_samples(v.front, v.side, v.side_face)]
    lens = estimate_distortion(samples, principal, radius)
    warnings = [f"{v.name}: {v.edges_dropped} refined edge(s) more than {edge_agree_px:g} px from the "
                "clicked corners at their ends not used (its clicks were)"
                for v in prepared if v.edges_dropped]
    problem, res = _fit(prepared, lens, principal, focal_px)
    nfev = int(res.nfev)
    offsets: dict[int, np.ndarray] = {}
    # Each view weighed by the noise its residuals show (twice: the residuals move with the fit).
    for _ in range(2):
        prepared = _measured_noise(prepared, problem, res.x)
        problem, res = _fit(prepared, lens, principal, focal_px, res.x)
        nfev += int(res.nfev)
    # Edge lines that are no edge of the shared box out first: they would bias the pose that the
    # rounding is read through.
    prepared, problem, res, offsets, work = _reject_lines(prepared, problem, res, lens, focal_px, scale,
                                                          None, offsets)
    nfev += work
    # The edges' rounding, read through the shared box, then taken out of the fit (twice: the
    # patterns depend on the pose they are computed at).
    rounding = _read_rounding(problem, res.x, lens, _mm_per_unit(scale, res.x))
    if rounding.read:
        for _ in range(2):
            offsets = _offsets(problem, res.x, rounding, rounding.radius_mm, _mm_per_unit(scale, res.x))
            prepared = _measured_noise(prepared, problem, res.x)
            problem, res = _fit(prepared, lens, principal, focal_px, res.x, offsets)
            nfev += int(res.nfev)
        # Judged again with the rounding taken out: a fold read at a place no view agrees with.
        prepared, problem, res, offsets, work = _reject_lines(prepared, problem, res, lens, focal_px, scale,
                                                              rounding, offsets)
        nfev += work
    disagreement: np.ndarray | None = None
    while len(prepared) >= 3:
        T, limit, work = _disagreements(problem, res, lens, focal_px, offsets)
        nfev += work
        worst = int(np.argmax(T))
        if not T[worst] > limit:
            disagreement = T
            break
        bad = prepared[worst]
        alone = bad.single  # what it measures by itself
        rest_x = _without(res.x, problem.n_shared, worst)
        prepared = [v for i, v in enumerate(prepared) if i != worst]
        problem, res = _fit(prepared, lens, principal, focal_px, rest_x, offsets)
        nfev += int(res.nfev)
        rest = _dims(scale, res.x[:2])
        left_out.append(LeftOut(
            bad.name, bad.index,
            f"disagrees with the other views beyond its noise (chi-square {T[worst]:.0f} on "
            f"{problem.n_shared} shared parameters, {OUTLIER_LEVEL:.1%} limit {limit:.0f}): alone it "
            f"measures {alone.width:.1f} x {alone.height:.1f} x {alone.depth:.1f} mm, the other views "
            f"{rest[0]:.1f} x {rest[1]:.1f} x {rest[2]:.1f} mm; check its points"))
    if len(prepared) == 2:
        T2, limit2, work = _disagreements(problem, res, lens, focal_px, offsets)
        nfev += work
        if T2[0] > limit2:
            warnings.append(f"{prepared[0].name} and {prepared[1].name} disagree beyond their noise "
                            f"(chi-square {T2[0]:.0f}, limit {limit2:.0f}); which one is wrong two views "
                            "cannot tell: add a third view or check their points")
    x = res.x
    cov = _covariance(problem, res)
    model, work = _model_sigma(problem, x, scale, focal_px, lens, rounding, offsets)
    nfev += work
    folds = _fold_sigma(problem, res, scale, rounding)
    sigma = np.sqrt(_dims_sigma(scale, x, cov) ** 2 + model**2 + folds**2)
    dims = _dims(scale, x[:2])
    free = focal_px is None
    focal = problem.focal(x)
    focal_std = float(focal * np.sqrt(max(cov[2, 2], 0.0))) if free else None
    fits = []
    for v, used in enumerate(prepared):
        n_lines = problem.n_lines[v]
        block = problem.view_px(x, v)
        pose = x[problem.n_shared + 6 * v: problem.n_shared + 6 * v + 6]
        fits.append(ViewFit(used.name, pose[:3].copy(), pose[3:].copy(),
                            _rms(block[n_lines:]), _rms(block[:n_lines]),
                            used.single, None if disagreement is None else float(disagreement[v]),
                            used.lines_rejected))
    warnings += [f"{f.name}: its clicks lie {f.click_rms_px:.1f} px (RMS) from the box the views share, "
                 f"more than {CLICK_WARN_PX:g} px: check its points" for f in fits
                 if f.click_rms_px > CLICK_WARN_PX]
    notes: tuple[str, ...] = ()
    if rounding.read:
        notes = (f"edges rounded {rounding.radius_mm:.1f} ± {rounding.std_mm:.1f} mm (read from the "
                 "shading at the folds of every view): the silhouettes' inset corrected",)
    a, b, c = (float(d) for d in dims)
    sa, sb, sc = (float(s) for s in sigma)
    result = Dimensions(a, b, c, "mm", True, notes, (sa, sb, sc))
    return JointResult(result, focal, focal_std, lens, tuple(fits),
                       tuple(sorted(left_out, key=lambda o: o.index)), tuple(warnings), nfev,
                       sum(v.lines_rejected for v in prepared))

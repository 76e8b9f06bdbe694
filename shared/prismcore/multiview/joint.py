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

The views measured alone are `multiview.views`; the least-squares problem they share,
`multiview.problem`; the rounding read through the shared box and the sigma of what the model
takes as known, `multiview.model_sigma`. Here: the fit's course, its outliers and its result.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import OptimizeResult
from scipy.stats import chi2

from prismcore.errors import InputError
from prismcore.geometry.evidence import box_edge_samples
from prismcore.geometry.lens import RadialDistortion, estimate_distortion
from prismcore.geometry.perspective import NOISE_LINE_PX, SIGMA_LINE_PX, line_terms
from prismcore.multiview.model_sigma import (
    _fold_sigma,
    _mm_per_unit,
    _model_sigma,
    _offsets,
    _read_rounding,
    _Rounding,
)
from prismcore.multiview.problem import _covariance, _dims, _dims_sigma, _fit, _only, _Problem, _without
from prismcore.multiview.views import View, _prepare, _Prepared
from prismcore.scan.measure import Dimensions
from prismcore.spec import KnownEdge

__all__ = ["CLICK_WARN_PX", "OUTLIER_LEVEL", "JointResult", "LeftOut", "View", "ViewFit", "fit_views"]

OUTLIER_LEVEL = 0.999
"""A view is left out when its disagreement with the others passes this chi-square quantile."""
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


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else 0.0


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
            face, side, _, _ = line_terms(problem.terms[v])[2 * k]
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

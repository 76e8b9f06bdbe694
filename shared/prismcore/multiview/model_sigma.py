"""What the joint fit's model takes as known, read and carried to the dimensions: the edges'
rounding read from every view's shading through the shared box and taken out as offsets of the
residuals, and the dimensions' 1-sigma from the lens distortion and the edge radius (refits at
+-1 sigma) and from where each rounded fold was found on its shading ramp.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult

from prismcore.geometry.lens import RadialDistortion
from prismcore.geometry.model_error import FOLD_FRACTION, ROUNDING_RMS_MM, edge_shifts, rounding_shifts
from prismcore.geometry.perspective import cauchy_weights, line_terms
from prismcore.geometry.rounding import STD_FLOOR_MM, RadiusEstimate
from prismcore.multiview.problem import _dims, _dims_gradient, _fit, _Problem
from prismcore.scan.measure import box_edge_radius
from prismcore.spec import KnownEdge

__all__: list[str] = []


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
    for v, view in enumerate(problem.views):
        found = box_edge_radius(view.image, problem.box_fit(x, v), lens, k)
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
    Jw = J * cauchy_weights(res.fun)[:, None]
    influence = -np.linalg.pinv(J.T @ Jw, rcond=1e-12)[:2] @ Jw.T  # d(W, D) / d(residuals)
    starts = np.r_[0, np.cumsum(problem.sizes)[:-1]]
    by_edge: dict[tuple[int, int], np.ndarray] = {}
    for v, view in enumerate(problem.views):
        terms = problem.terms[v]
        rows = line_terms(terms)
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

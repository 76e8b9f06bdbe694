"""How much a least-squares fit rests on any one stretch of its data: a grouped jackknife.

A box fitted to an outline whose stretches agree moves little when any one of them is left out;
one fitted to an outline with a stretch that is not the box's (a shadow taken for the part, a
face lost against the support, a side mirroring it) moves by about that stretch's error. The
spread of the leave-one-group-out fits is then a sigma that covers errors the outline's own
noise does not show.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

__all__ = ["jackknife_cov", "soft_l1_weights"]

_AGREEING = 0.99  # a group's step under this quantile of its noise's chi-square agrees with the rest
_RIDGE = 1e-9  # of the normal matrix's trace: a group whose removal leaves a direction unknown


def soft_l1_weights(residuals: np.ndarray, f_scale: float) -> np.ndarray:
    """The weights (N,) under which a soft-l1 fit (scipy's `loss="soft_l1"`) is, at its solution,
    a weighted least-squares fit: rho'(z) = (1 + z) ** -0.5 with z = (r / f_scale) ** 2."""
    z = np.square(residuals / f_scale)
    return np.asarray(1.0 / np.sqrt(1.0 + z), np.float64)


def jackknife_cov(
    J: np.ndarray, r: np.ndarray, w: np.ndarray, groups: list[np.ndarray], noise_var: float | None = None
) -> np.ndarray:
    """The grouped jackknife's covariance of a weighted least-squares solution.

    Each group's removal is taken to first order: at a solution of min sum w r^2 (J^T W r = 0),
    the fit without group g moves by (A - A_g)^-1 J_g^T W_g r_g, with A = J^T W J.

    Parameters
    ----------
    J : ndarray, shape (N, P), float64
        The residuals' Jacobian at the solution (unweighted).
    r : ndarray, shape (N,), float64
        The residuals at the solution.
    w : ndarray, shape (N,), float64
        Each residual's weight (1 for plain least squares).
    groups : list of ndarray of int
        The residuals' indices of each group left out in turn (at least two groups).
    noise_var : float, optional
        The residuals' variance under the fit's own noise model. Given, a group whose removal
        moves the fit no more than that noise would (its step's chi-square, against the step's
        covariance noise_var * ((A - A_g)^-1 - A^-1), under its 99th percentile) counts as
        agreeing and adds nothing: a group whose removal leaves a direction poorly known moves
        the fit by its noise, amplified, and that is no disagreement.

    Returns
    -------
    ndarray, shape (P, P), float64
        (G - 1) / G * sum_g d_g d_g^T, d_g each group's removal's step: the parameters' covariance
        as the groups' disagreement shows it.
    """
    g = len(groups)
    p = J.shape[1]
    if g < 2:
        return np.zeros((p, p))
    Jw = J * w[:, None]
    A = J.T @ Jw
    ridge = _RIDGE * float(np.trace(A)) * np.eye(p)
    A_inv = np.linalg.inv(A + ridge)
    limit = float(chi2.ppf(_AGREEING, p))
    steps = []
    for idx in groups:
        Ag = J[idx].T @ Jw[idx]
        bg = Jw[idx].T @ r[idx]
        reduced_inv = np.linalg.inv(A - Ag + ridge)
        step = reduced_inv @ bg
        if noise_var is not None:
            cov = noise_var * (reduced_inv - A_inv)
            if float(step @ np.linalg.pinv(cov, rcond=1e-10, hermitian=True) @ step) <= limit:
                step = np.zeros(p)
        steps.append(step)
    D = np.asarray(steps)
    return np.asarray((g - 1) / g * D.T @ D, np.float64)

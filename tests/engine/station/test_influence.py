"""The grouped jackknife of a fit (`influence.jackknife_cov`) against its oracle: each group's
fit really redone without it. And the box fit's use of it: a silhouette whose sides disagree is
given a sigma that covers the disagreement."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from prismcore.station.influence import jackknife_cov, soft_l1_weights


@pytest.mark.parametrize("seed", range(5))
def test_the_jackknife_of_a_linear_fit_is_its_refits_without_each_group(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, p = 60, 4
    J = rng.normal(size=(n, p))
    y = J @ rng.normal(size=p) + rng.normal(0, 0.1, n)
    y[:10] += 2.0  # one group that disagrees with the rest
    w = rng.uniform(0.5, 1.5, n)
    sw = np.sqrt(w)
    x = np.linalg.lstsq(J * sw[:, None], y * sw, rcond=None)[0]
    r = J @ x - y
    groups = [np.arange(k, k + 10) for k in range(0, n, 10)]
    steps = []
    for g in groups:
        keep = np.setdiff1d(np.arange(n), g)
        xg = np.linalg.lstsq(J[keep] * sw[keep, None], y[keep] * sw[keep], rcond=None)[0]
        steps.append(xg - x)
    D = np.array(steps)
    oracle = (len(groups) - 1) / len(groups) * D.T @ D
    np.testing.assert_allclose(jackknife_cov(J, r, w, groups), oracle, rtol=1e-4, atol=1e-9)  # the ridge
    # the group that disagrees moves the fit most
    assert np.argmax(np.linalg.norm(D, axis=1)) == 0


def test_soft_l1_weights_make_scipys_robust_solution_a_weighted_least_squares_one() -> None:
    """At least_squares' soft-l1 optimum, J^T W r = 0 with W the weights: what the jackknife's
    first-order step assumes."""
    rng = np.random.default_rng(7)
    J = rng.normal(size=(80, 3))
    y = J @ np.array([1.0, -2.0, 0.5]) + rng.normal(0, 0.2, 80)
    y[:8] += 5.0
    fit = least_squares(
        lambda x: J @ x - y, np.zeros(3), loss="soft_l1", f_scale=1.0, xtol=1e-14, ftol=1e-14, gtol=1e-14
    )
    g = J.T @ (soft_l1_weights(fit.fun, 1.0) * fit.fun)
    assert np.abs(g).max() < 1e-8 * np.abs(J.T @ fit.fun).max() + 1e-9


def test_one_group_gives_no_spread() -> None:
    J = np.eye(3)
    assert not jackknife_cov(J, np.ones(3), np.ones(3), [np.arange(3)]).any()

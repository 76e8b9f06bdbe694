"""Pooling per-photo focal estimates of one camera: the inverse-variance mean when they agree,
a wider error when they scatter, outliers left out, checked against direct computation and
against draws with known truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prismcore.video.pooling import pool_focal


def test_agreeing_estimates_give_the_inverse_variance_mean():
    pooled = pool_focal([(1000.0, 10.0), (1010.0, 20.0), (995.0, 10.0)])
    w = np.array([1 / 100, 1 / 400, 1 / 100])
    f = np.array([1000.0, 1010.0, 995.0])
    assert pooled.focal_px == pytest.approx(float(np.sum(w * f) / w.sum()))
    chi2 = float(np.sum(w * (f - pooled.focal_px) ** 2)) / 2
    assert pooled.std_px == pytest.approx(math.sqrt(max(1, chi2)) / math.sqrt(w.sum()))
    assert pooled.used == (0, 1, 2)


def test_a_wild_estimate_is_left_out():
    estimates = [(600.0, 8.0), (610.0, 9.0), (605.0, 7.0), (598.0, 10.0), (1400.0, 5.0)]
    pooled = pool_focal(estimates)
    assert pooled.used == (0, 1, 2, 3)
    assert 598 < pooled.focal_px < 610


def test_unusable_estimates_are_ignored_and_none_left_gives_none():
    assert pool_focal([]) is None
    assert pool_focal([(math.nan, 1.0), (500.0, 0.0), (-3.0, 1.0)]) is None
    pooled = pool_focal([(math.nan, 1.0), (700.0, 7.0)])
    assert pooled.focal_px == 700.0 and pooled.std_px == 7.0 and pooled.used == (1,)


@pytest.mark.parametrize("seed", range(5))
def test_pooled_error_covers_the_truth(seed):
    rng = np.random.default_rng(seed)
    truth = 820.0
    sigmas = rng.uniform(5, 40, size=12)
    estimates = [(truth + rng.normal(0, s), s) for s in sigmas]
    pooled = pool_focal(estimates)
    single = float(np.median(sigmas))
    assert abs(pooled.focal_px - truth) < 3 * pooled.std_px
    assert pooled.std_px < single  # steadier than a typical single frame

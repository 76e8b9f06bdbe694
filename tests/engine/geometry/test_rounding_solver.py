"""The fold fit's batched least squares (`prismcore.geometry.rounding.fold_profile_radius`) against the
plain oracle it replaced: one `np.linalg.lstsq` per (radius, blur, offset) candidate.

Its decisions (the radius, the offset) must be the same, and every candidate's residual equal to
rounding: a batched solve that ranked candidates differently would be a new knife edge.
"""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from prismcore.geometry import rounding as R  # noqa: N812 (the module under test, short)


def _oracle(profile: np.ndarray, x_px: np.ndarray, px_per_mm: tuple[float, float],
            tan_phi: tuple[float, float]) -> tuple[float, float, np.ndarray]:
    step = R._STEP_PX
    pad = math.ceil(3.5 * max(R._BLURS_PX) / step) + math.ceil(max(R._SHIFTS_PX) / step)
    fine = x_px[0] + step * np.arange(-pad, x_px.size + pad)
    on_a = fine < 0
    slopes = np.stack([np.where(on_a, fine, 0.0), np.where(on_a, 0.0, fine)], axis=1) / x_px.size
    rss = np.full(R._RADII_MM.size, np.inf)
    best_shift = np.zeros(R._RADII_MM.size)
    for i, r in enumerate(R._RADII_MM):
        a = R._arc_of(np.clip(-fine, 0, None) / px_per_mm[0], float(r), tan_phi[0])
        b = R._arc_of(np.clip(fine, 0, None) / px_per_mm[1], float(r), tan_phi[1])
        turn = np.where(on_a, a, b)
        basis = np.column_stack([np.where(on_a, np.cos(a), np.sin(b)), np.where(on_a, np.sin(a), np.cos(b)),
                                 1 - np.cos(turn) - np.sin(turn)])
        if r == 0:
            basis = basis[:, :2]
        for sigma in R._BLURS_PX:
            k = R._gauss(sigma)
            blurred = np.stack([np.convolve(np.pad(col, k.size // 2, mode="edge"), k, mode="valid")
                                for col in basis.T], axis=1)
            blurred = np.column_stack([blurred, slopes])
            for shift in R._SHIFTS_PX:
                lo = pad + round(shift / step)
                A = blurred[lo:lo + x_px.size]
                coef, *_ = np.linalg.lstsq(A, profile, rcond=None)
                got = float(((A @ coef - profile) ** 2).sum())
                if got < rss[i]:
                    rss[i], best_shift[i] = got, shift
    best = int(np.argmin(rss))
    return float(R._RADII_MM[best]), float(best_shift[best]), rss


def _fold(seed: int, sharpness: tuple[float, float] = (1.5, 8.0)
          ) -> tuple[np.ndarray, np.ndarray, tuple[float, float], tuple[float, float]]:
    """A fold's luma profile as a photo shows one: two face levels, a ramp of some radius, blur,
    print-like texture and noise, as float32 (the sampler's type); `sharpness` the range of image
    px per mm drawn."""
    rng = np.random.default_rng(seed)
    g = (float(rng.uniform(*sharpness)), float(rng.uniform(*sharpness)))
    tan_phi = (float(rng.uniform(0.2, 2.0)), float(rng.uniform(0.2, 2.0)))
    x = np.arange(-R._HALF_WIDTH_MM * g[0], R._HALF_WIDTH_MM * g[1], R._STEP_PX)
    radius = float(rng.choice([0.0, 0.4, 1.3, 2.5]))
    s = np.where(x < 0, -x / g[0], x / g[1])
    ramp = np.clip(0.5 + np.sign(x) * np.minimum(s, radius + 1e-9) / (2 * radius + 1e-9), 0, 1)
    levels = rng.uniform(40, 220, 2)
    luma = levels[0] + (levels[1] - levels[0]) * ramp + 4 * np.sin(x / rng.uniform(2, 9))
    luma = luma + rng.normal(0, 1.5, x.size)
    return luma[:, None].astype(np.float32), x, g, tan_phi


@pytest.mark.parametrize(("seed", "sharpness"), [*((s, (1.5, 8.0)) for s in range(12)),
                                                 (12, (40.0, 60.0)), (13, (90.0, 110.0))])
def test_the_batched_fit_decides_as_one_lstsq_per_candidate(seed: int, sharpness) -> None:
    profile, x, g, tan_phi = _fold(seed, sharpness)
    radius, shift, rss = R.fold_profile_radius(profile, x, g, tan_phi)
    want_radius, want_shift, want_rss = _oracle(profile, x, g, tan_phi)
    assert (radius, shift) == (want_radius, want_shift)
    np.testing.assert_allclose(rss, want_rss, rtol=1e-11)


def test_an_ill_conditioned_window_is_solved_by_lstsq_itself() -> None:
    rng = np.random.default_rng(3)
    columns = rng.normal(size=(2, 60, 4))
    columns[1, :, 3] = columns[1, :, 2]  # two equal columns: rank 3, the normal equations singular
    y = rng.normal(size=(40, 1)) * 30 + 100
    starts = np.array([0, 7, 20])
    got = R._window_rss(columns, starts, y.astype(np.float32))
    for b in range(2):
        for j, s in enumerate(starts):
            A = columns[b, s:s + 40]
            coef, *_ = np.linalg.lstsq(A, y.astype(np.float32), rcond=None)
            assert got[b, j] == pytest.approx(float(((A @ coef - y.astype(np.float32)) ** 2).sum()), rel=1e-9)


def test_a_sharp_photos_long_profile_is_fitted_in_bounded_memory() -> None:
    # 100 px per mm (a 12-megapixel photo of a small part): 5,200 samples across the fold. All
    # 1,599 candidates' designs at once took 740 MB; in chunks the fit holds under 150 MB.
    profile, x, g, tan_phi = _fold(1, (100.0, 100.0))
    tracemalloc.start()
    try:
        R.fold_profile_radius(profile, x, g, tan_phi)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert x.size > 5000 and peak < 150 * 2**20, peak / 2**20

"""The segmentation's pieces against their plain definitions."""

from __future__ import annotations

import numpy as np

from prismcore.station.segment import SHADOW_RANGE, _gain, _residual


def _difference(P: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """The photo's distance from the support scaled by the best shadow factor, as first written."""
    dot = np.einsum("ijc,ijc->ij", P, bg)
    nb = np.einsum("ijc,ijc->ij", bg, bg) + 1.0
    s = np.clip(dot / nb, *SHADOW_RANGE)
    return np.linalg.norm(P - np.minimum(s[..., None] * bg, 255.0), axis=2)


def test_the_residual_is_the_least_difference_over_the_support_shifted_a_pixel_each_way() -> None:
    rng = np.random.default_rng(1)
    P = rng.uniform(0, 255, (37, 53, 3)).astype(np.float32)
    bg = rng.uniform(0, 300, (37, 53, 3)).astype(np.float32)  # a brighter light: over 255 too
    expected = _difference(P, bg)
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        expected = np.minimum(expected, _difference(P, np.roll(bg, (dy, dx), axis=(0, 1))))
    np.testing.assert_allclose(_residual(P, bg), expected, rtol=1e-4, atol=1e-3)


def test_the_lights_gain_is_measured_or_said_to_be_unknown() -> None:
    rng = np.random.default_rng(2)
    bg = rng.uniform(60, 200, (40, 40, 3)).astype(np.float32)
    gain, warning = _gain(bg * np.float32(1.1), bg)
    assert np.allclose(gain, 1.1, atol=1e-3) and warning is None
    clipped = np.full((40, 40, 3), 250, np.float32)  # the support clipped everywhere
    gain, warning = _gain(clipped, clipped)
    assert np.all(gain == 1) and warning is not None and "could not be measured" in warning

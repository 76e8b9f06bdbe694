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


def _difference_clipped(P: np.ndarray, bg: np.ndarray, clipped: np.ndarray) -> np.ndarray:
    """As `_difference`, a clipped channel of the plate a lower bound: only a darker photo differs."""
    dot = np.einsum("ijc,ijc->ij", P, bg)
    nb = np.einsum("ijc,ijc->ij", bg, bg) + 1.0
    s = np.clip(dot / nb, *SHADOW_RANGE)
    e = P - np.minimum(s[..., None] * bg, 255.0)
    e = np.where(clipped, np.minimum(e, 0.0), e)
    return np.linalg.norm(e, axis=2)


def test_a_channel_clipped_in_the_plate_differs_only_where_the_photo_is_darker() -> None:
    rng = np.random.default_rng(3)
    P = rng.uniform(0, 255, (31, 41, 3)).astype(np.float32)
    bg = rng.uniform(0, 255, (31, 41, 3)).astype(np.float32)
    clipped = rng.uniform(size=(31, 41, 3)) < 0.3
    bg[clipped] = 255.0
    expected = _difference_clipped(P, bg, clipped)
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        shifted = (np.roll(bg, (dy, dx), axis=(0, 1)), np.roll(clipped, (dy, dx), axis=(0, 1)))
        expected = np.minimum(expected, _difference_clipped(P, *shifted))
    np.testing.assert_allclose(_residual(P, bg, clipped=clipped), expected, rtol=1e-4, atol=1e-3)
    # A sheet clipped blue in the plate, shown by a photo exposed shorter (prismpbr report station
    # 500109's levels): its blue no longer counts against it.
    plate = np.tile(np.array([203, 235, 255], np.float32), (20, 20, 1))
    photo = np.tile(np.array([178, 211, 243], np.float32), (20, 20, 1))
    toned = plate * np.float32(0.877)
    with_clip = float(_residual(photo, toned, clipped=plate >= 254).max())
    assert with_clip < 0.7 * float(_residual(photo, toned).min())

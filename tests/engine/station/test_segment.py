"""The segmentation's pieces against their plain definitions."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.errors import PartRefusedError
from prismcore.station.segment import SHADOW_RANGE, _gain, _residual, _unseen, segment_part


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


def test_where_the_plate_does_not_reach_is_unseen_with_a_pixel_around() -> None:
    shift = np.array([[1.0, 0, 20], [0, 1, 0], [0, 0, 1]])  # the plate 20 px right in the photo
    unseen = _unseen((60, 80), shift, (80, 60))
    assert unseen[:, :21].all() and not unseen[:, 21:].any()  # 20 columns, and a pixel around


def _textured(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """A support of coarse squares of random colours (a table's pattern, sharp at each square's edge)."""
    h, w = shape
    cells = rng.uniform(30, 230, (h // 8 + 1, w // 8 + 1, 3))
    return np.repeat(np.repeat(cells, 8, axis=0), 8, axis=1)[:h, :w].astype(np.uint8)


def test_a_camera_moved_shows_more_scene_and_still_finds_the_one_part() -> None:
    """The photo taken after the camera moved 48 px: its left band shows a support the plate never
    saw. The warp's replicated border is no support: one part is found, not two (before, that
    band's difference from the replicated column was a second 'part')."""
    rng = np.random.default_rng(5)
    h, w, moved = 240, 520, 48
    scene = _textured(rng, (h, w + moved))  # the support as wide as both views
    plate = np.ascontiguousarray(scene[:, moved:])  # the calibrated view
    photo = scene[:, :w].copy()  # the camera turned: the scene `moved` px to the right
    photo[80:160, 200:330] = (200, 40, 30)  # the part, well inside
    to_photo = np.array([[1.0, 0, moved], [0, 1, 0], [0, 0, 1]])  # plate pixel -> photo pixel
    sil = segment_part(photo, plate, to_photo)
    ys, xs = np.nonzero(sil.mask)
    box = np.array([xs.min(), xs.max(), ys.min(), ys.max()])
    assert np.abs(box - (200, 329, 80, 159)).max() <= 1, box  # a pixel: the residual's own tolerance
    assert not sil.others and not sil.warnings, (sil.others, sil.warnings)


def test_a_part_reaching_where_the_plate_shows_nothing_is_refused() -> None:
    rng = np.random.default_rng(6)
    h, w, moved = 240, 520, 48
    scene = _textured(rng, (h, w + moved))
    plate = np.ascontiguousarray(scene[:, moved:])
    photo = scene[:, :w].copy()
    photo[80:160, 30:160] = (200, 40, 30)  # from the unseen band into the seen support
    with pytest.raises(PartRefusedError, match="where the empty support's photo shows nothing"):
        segment_part(photo, plate, np.array([[1.0, 0, moved], [0, 1, 0], [0, 0, 1]]))

"""The segmentation's residual computed only round the part gives every pixel it computes the
value the whole window's residual gives it (the oracle: `_residual` over the whole window)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from prismcore.station.segment import _INSIDE, _STRIP, _residual


@pytest.mark.parametrize("seed", range(6))
def test_the_residual_round_the_part_is_the_whole_windows_where_computed(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(40, 260, 2))
    bg = rng.uniform(0, 255, (h, w, 3)).astype(np.float32)
    P = bg * rng.uniform(0.5, 1.1, (h, w, 1)).astype(np.float32)  # a shadow, say
    core = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(core, np.array([[w * 0.2, h * 0.1], [w * 0.9, h * 0.3], [w * 0.7, h * 0.95],
                                       [w * 0.1, h * 0.8]], np.int32), 1)
    P[core > 0] = rng.uniform(0, 255, 3).astype(np.float32)  # the part
    whole = _residual(P, bg)
    around = _residual(P, bg, core > 0)
    computed = around != _INSIDE
    np.testing.assert_array_equal(around[computed], whole[computed])
    # what was left out is inside the core, whole strips' runs of it
    assert not (~computed & (core == 0)).any()
    if h >= 2 * _STRIP and w >= 100:
        assert (~computed).sum() > 0.2 * core.sum()


def test_without_a_core_every_pixel_is_computed() -> None:
    rng = np.random.default_rng(9)
    bg = rng.uniform(0, 255, (70, 90, 3)).astype(np.float32)
    P = rng.uniform(0, 255, (70, 90, 3)).astype(np.float32)
    np.testing.assert_array_equal(_residual(P, bg, np.zeros((70, 90), bool)), _residual(P, bg))

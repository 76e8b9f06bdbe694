"""decimate: the display preview of a cloud is an even, deterministic subset of it."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore import InputError
from prismcore.scan.cloud import PREVIEW_POINTS, Cloud, decimate


def _cloud(n: int) -> Cloud:
    rng = np.random.default_rng(n)
    return Cloud(rng.normal(size=(n, 3)).astype(np.float32), rng.integers(0, 256, (n, 3), dtype=np.uint8))


@pytest.mark.parametrize(("n", "cap"), [(10, 3), (1000, 999), (12345, 100), (7, 1)])
def test_a_large_cloud_keeps_exactly_cap_points_evenly_spread(n, cap):
    cloud = _cloud(n)
    before = cloud.points.copy()
    small = decimate(cloud, cap)
    assert len(small.points) == len(small.colors) == cap
    # Every kept point is the cloud's own, in order, with its own colour.
    index = {tuple(p): i for i, p in enumerate(cloud.points.tolist())}
    kept = np.array([index[tuple(p)] for p in small.points.tolist()])
    assert np.all(np.diff(kept) > 0)
    np.testing.assert_array_equal(small.colors, cloud.colors[kept])
    # Even: the gaps between kept indices differ by at most one.
    gaps = np.diff(np.append(kept, n + kept[0]))
    assert gaps.max() - gaps.min() <= 1
    np.testing.assert_array_equal(cloud.points, before)  # input untouched
    again = decimate(cloud, cap)
    np.testing.assert_array_equal(again.points, small.points)


@pytest.mark.parametrize("n", [0, 5, PREVIEW_POINTS])
def test_a_small_cloud_is_returned_whole(n):
    cloud = _cloud(n)
    assert decimate(cloud) is cloud


@pytest.mark.parametrize("cap", [0, -3])
def test_a_cap_below_one_is_refused(cap):
    with pytest.raises(InputError, match=f"got {cap}"):
        decimate(_cloud(10), cap)

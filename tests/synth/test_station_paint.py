"""prismsynth paints a station part's faces by the share of each pixel they cover: the painted
area is the polygon's own (the shoelace formula's), whichever way round it is given, and a side
lying on a row of pixel centres paints that row half. OpenCV's anti-aliased fill painted every
pixel an edge touched, each side ~0.45 px too far out, and a correct station read long."""

from __future__ import annotations

import numpy as np
import pytest

from prismsynth.station import _fill_exact


def _shoelace(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))


def _convex(rng: np.random.Generator) -> np.ndarray:
    """A random convex polygon of 3-8 corners well inside a 200 x 160 canvas, counter-clockwise."""
    n = int(rng.integers(3, 9))
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    radius = rng.uniform(15, 60)
    centre = rng.uniform([70, 70], [130, 90])
    return centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("reverse", [False, True])
def test_the_painted_area_is_the_polygons(seed, reverse):
    poly = _convex(np.random.default_rng(seed))
    poly = poly[::-1] if reverse else poly
    img = np.zeros((160, 200, 3), np.float32)
    _fill_exact(img, poly, np.ones(3))
    # exact along the sides; a corner sharper than a right angle is painted a little over
    assert img[..., 0].sum() == pytest.approx(_shoelace(poly), abs=0.25 * len(poly))
    assert img.min() >= 0 and img.max() <= 1


@pytest.mark.parametrize("offset", [0.0, 0.25, 0.5])
def test_a_side_paints_the_pixels_it_crosses_by_their_share(offset):
    # a rectangle from x = 10.5 + offset: the column at x = 10 + 1 is covered by 1 - offset, and the
    # one before it by nothing; its colour is blended, not replaced
    poly = np.array([[10.5 + offset, 5.0], [40.5, 5.0], [40.5, 30.0], [10.5 + offset, 30.0]])
    img = np.full((40, 60, 3), 100.0, np.float32)
    _fill_exact(img, poly, np.array([200.0, 200.0, 200.0]))
    assert img[15, 11, 0] == pytest.approx(100 + 100 * (1 - offset), abs=1e-3)
    assert img[15, 10, 0] == pytest.approx(100.0)
    assert img[15, 20, 0] == pytest.approx(200.0)

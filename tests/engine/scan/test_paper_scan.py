"""The vectorised paper scan against a literal per-pixel reading of the paper."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.scan.colour_scan import paper_colour_scan


def paper_scan_literal(pixels: np.ndarray, seed: np.ndarray, tol: float) -> np.ndarray:
    """The paper, pixel by pixel: the oracle (slow on purpose)."""
    rows, cols, _ = pixels.shape
    out = np.zeros((rows, cols), dtype=bool)
    for r in range(rows):
        scale = seed.astype(float)
        for c in range(cols):
            colour = pixels[r, c].astype(float)
            if any(abs(colour[k] - scale[k]) > tol for k in range(3)):
                scale = colour  # a contradicting pixel opens a new colour scale
            out[r, c] = all(abs(scale[k] - seed[k]) <= tol for k in range(3))
    return out


@pytest.mark.parametrize("tol", [0, 5, 12, 30])
@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_matches_literal_reading(rng, tol, dtype):
    base = rng.integers(0, 256, size=(1, 1, 3))
    pixels = np.clip(base + rng.normal(0, 10, size=(23, 31, 3)), 0, 255).astype(dtype)
    pixels[5:9, 10:20] = 255 - pixels[5:9, 10:20]  # a label of another colour
    seed = pixels[0, 0].astype(np.float64)
    expected = paper_scan_literal(pixels, seed, tol)
    np.testing.assert_array_equal(paper_colour_scan(pixels, seed, tol), expected)


def test_papers_example_colour_is_same_scale():
    # The paper: after (235, 39, 84), values down to (223, 27, 72) count as the same colour.
    pixels = np.array([[[235, 39, 84], [223, 27, 72], [222, 27, 72]]], dtype=np.uint8)
    out = paper_colour_scan(pixels, np.array([235.0, 39, 84]), 12)
    assert out.tolist() == [[True, True, False]]


def test_input_not_mutated(rng):
    pixels = rng.integers(0, 256, size=(8, 9, 3)).astype(np.uint8)
    before = pixels.copy()
    paper_colour_scan(pixels, pixels[0, 0].astype(float), 12)
    np.testing.assert_array_equal(pixels, before)

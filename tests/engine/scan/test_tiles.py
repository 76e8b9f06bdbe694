"""Row tiles merge into exactly the whole-face result, for both methods."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from prismcore import ScanSpec
from prismcore.scan.colour_scan import merge_bands, row_tiles, scan_band
from prismcore.scan.pipeline import plan_scan, scan_face


def _image(rng) -> np.ndarray:
    img = rng.integers(0, 60, size=(300, 400, 3)).astype(np.uint8)
    img[50:250, 60:260] = (200, 160, 90)
    img[50:250, 260:340] = (150, 120, 70)
    img[100:140, 100:200] = (20, 20, 200)  # a label
    noise = rng.normal(0, 4, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


POINTS = [[61, 51], [258, 49], [261, 249], [262, 50], [339, 52]]


@pytest.mark.parametrize("method", ["default", "paper"])
@pytest.mark.parametrize("tiles", [2, 3, 7, 64, 1000])
def test_tiles_equal_whole(rng, method, tiles):
    image = _image(rng)
    plan = plan_scan(ScanSpec(image="x", points=POINTS, method=method), image)
    for face in plan.faces:
        whole = scan_face(image, face, tiles=1)
        bands = [scan_band(image, face, r0, r1) for r0, r1 in row_tiles(face, tiles)]
        tiled = merge_bands(face, bands[::-1][::-1])
        np.testing.assert_array_equal(tiled.object_mask, whole.object_mask)
        np.testing.assert_array_equal(tiled.marked_mask, whole.marked_mask)
        assert whole.object_mask.any()


@pytest.mark.parametrize("count", [1, 2, 5, 1000])
def test_row_tiles_cover_window_once(rng, count):
    image = _image(rng)
    face = plan_scan(ScanSpec(image="x", points=POINTS), image).faces[0]
    bands = row_tiles(face, count)
    rows = face.window[1] - face.window[0]
    assert bands[0][0] == 0 and bands[-1][1] == rows
    assert all(a[1] == b[0] for a, b in itertools.pairwise(bands))
    assert len(bands) <= count

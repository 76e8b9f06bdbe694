"""`prismcore.outputs.las.write_las` read back by laspy (the independent reader), on clouds made to
probe its record building: every point in order across the writer's blocks, each coordinate
within half a 0.1 mm grid step of (x, z, -y) / 1000 m written out here, ties at 0.05 mm, both
dtypes, with and without colours, LAS and LAZ.
"""

from __future__ import annotations

import io

import laspy
import numpy as np
import pytest

from prismcore.outputs import las as las_module
from prismcore.outputs.las import write_las


def _cloud(n: int, dtype: type, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pts = rng.normal(0.0, 400.0, (n, 3))
    pts[: n // 4] = np.round(pts[: n // 4], 1) + 0.05  # on the 0.05 mm ties of the 0.1 mm grid
    return pts.astype(dtype)


@pytest.mark.parametrize("compressed", [False, True])
@pytest.mark.parametrize("colored", [False, True])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("n", [1, 7, 2500])
def test_every_point_on_the_grid_in_order(n: int, dtype: type, colored: bool, compressed: bool,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(las_module, "_CHUNK", 1000)  # several blocks, the last one short
    points = _cloud(n, dtype, seed=n)
    colors = np.random.default_rng(n + 1).integers(0, 256, (n, 3), dtype=np.uint8) if colored else None
    buf = io.BytesIO()
    write_las(buf, points, colors, compressed=compressed)
    got = laspy.read(io.BytesIO(buf.getvalue()))
    assert got.header.point_count == n
    p = points.astype(np.float64)
    metres = np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]) / 1000.0
    xyz = np.column_stack([got.X, got.Y, got.Z]).astype(np.float64) * 1e-4  # the stored integers
    assert np.abs(xyz - metres).max() <= 0.5e-4 * (1 + 1e-9)
    rgb = np.column_stack([got.red, got.green, got.blue])
    if colors is None:
        assert not rgb.any()
    else:
        assert np.array_equal(rgb, colors.astype(np.uint16) * 257)
    assert not np.column_stack([got.intensity, got.classification, got.return_number]).any()

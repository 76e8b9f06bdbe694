"""The edge radius read from the shading at a box's folds (`prismcore.geometry.rounding`).

Oracle: photo-like renders (`prismsynth.photo_like_scene`) of a known radius, read through the
render's true camera (pose, focal length, distortion), so that only the estimator is tested.
"""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.geometry.rounding import _sample, estimate_edge_radius
from prismsynth import PhotoLikeScene, photo_like_scene
from prismsynth.phone import distort_points

pytestmark = pytest.mark.slow  # one photo-like render per case


def _estimate(p: PhotoLikeScene):  # type: ignore[no-untyped-def]
    s = p.scene
    K, R, t = s.camera_matrix, s.rotation, s.translation
    assert s.distortion is not None

    def to_image(world: np.ndarray) -> np.ndarray:
        cam = world @ R.T + t
        return distort_points(cam[:, :2] / cam[:, 2:] * K[0, 0] + K[:2, 2], K, s.distortion)

    size = np.array([p.box.width_mm, p.box.height_mm, p.box.depth_mm])
    return estimate_edge_radius(p.image, to_image, size, -R.T @ t)


@pytest.mark.parametrize("seed", [9, 13])
@pytest.mark.parametrize("radius", [1.6, 2.4])
def test_radius_read_within_its_uncertainty(seed: int, radius: float) -> None:
    est = _estimate(photo_like_scene(seed, edge_radius_mm=radius))
    assert est is not None
    assert abs(est.radius_mm - radius) <= max(0.5, 2 * est.std_mm), est
    assert est.std_mm < 1.0, est


@pytest.mark.parametrize("seed", [1, 16])
def test_folds_that_disagree_give_no_radius_rather_than_a_wrong_one(seed: int) -> None:
    """Views where one fold's shading is unreadable (print on it, a face seen grazing)."""
    est = _estimate(photo_like_scene(seed, edge_radius_mm=2.4))
    assert est is None or abs(est.radius_mm - 2.4) <= max(0.5, 2 * est.std_mm), est


def test_a_larger_radius_reads_larger() -> None:
    small, large = (_estimate(photo_like_scene(9, edge_radius_mm=r)) for r in (0.6, 2.4))
    assert large is not None
    assert small is None or large.radius_mm - small.radius_mm >= 1.0, (small, large)


@pytest.mark.parametrize("seed", [0, 8])
def test_sharp_box_gives_no_radius(seed: int) -> None:
    """The two sharp renders (of 12 tried) whose folds look most like a rounding (print near
    them, faces seen at a grazing angle): still no evidence of one."""
    assert _estimate(photo_like_scene(seed, edge_radius_mm=0.0)) is None


def test_sampling_more_points_than_one_remap_takes():
    # cv2.remap's maps are images capped below 32767 a side; a long fold profile must not crash
    # (found by the spec fuzz test on a large photo), and must equal bilinear interpolation.
    rng = np.random.default_rng(5)
    image = rng.random((50, 60, 3), dtype=np.float32)
    pts = rng.random((70_000, 2)) * [59, 49]
    got = _sample(image, pts)
    x0, y0 = np.floor(pts[:, 0]).astype(int), np.floor(pts[:, 1]).astype(int)
    fx, fy = (pts[:, 0] - x0)[:, None], (pts[:, 1] - y0)[:, None]
    want = (image[y0, x0] * (1 - fx) * (1 - fy) + image[y0, x0 + 1] * fx * (1 - fy)
            + image[y0 + 1, x0] * (1 - fx) * fy + image[y0 + 1, x0 + 1] * fx * fy)
    assert got.shape == (70_000, 3) and np.abs(got - want).max() < 1e-4

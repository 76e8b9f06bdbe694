"""The height read where the support's pattern is hidden below the part's top
(prismcore.station.hidden_sides), on scenes drawn here from the geometry alone: a checkered
support seen by a pinhole camera, a box whose top is bright and whose sides mirror the support
(the support's own pattern, reflected: the same levels, another arrangement), and a box that is
truly as low as the outline says (nothing under its top but the support)."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.station.boxfit import OutlineFit, box_corners, project
from prismcore.station.hidden_sides import _box_under, evidence_enough, read_hidden_sides, widened

W, H = 1280, 960
K = np.array([[1000.0, 0, 640], [0, 1000.0, 480], [0, 0, 1]])
SQUARE_MM = 20.0
IDENTITY_TONE = np.tile(np.arange(256, dtype=np.float32), (3, 1))


def _pose(elevation_deg: float, distance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The camera looking at the board's origin from `elevation_deg` above the support (the
    board's z points into the support): R, t (board -> camera)."""
    e = np.radians(elevation_deg)
    centre = np.array([0.0, -distance_mm * np.cos(e), -distance_mm * np.sin(e)])
    forward = -centre / np.linalg.norm(centre)
    right = np.array([1.0, 0.0, 0.0])
    down = np.cross(forward, right)
    R = np.vstack([right, down, forward])
    return R, -R @ centre


def _plane_points(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Where each pixel's ray meets the support (z = 0): (H, W, 2) mm."""
    u, v = np.meshgrid(np.arange(W) + 0.0, np.arange(H) + 0.0)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ (R.T @ np.linalg.inv(K)).T
    centre = -R.T @ t
    lam = -centre[2] / rays[..., 2]
    return centre[:2] + lam[..., None] * rays[..., :2]


def _checker(xy: np.ndarray) -> np.ndarray:
    """The support's pattern at plane points (..., 2) mm: (..., 3) uint8 RGB."""
    cells = np.floor(xy / SQUARE_MM).astype(int)
    level = np.where((cells[..., 0] + cells[..., 1]) % 2 == 0, 215, 45)
    return np.repeat(level[..., None], 3, axis=-1).astype(np.uint8)


def _fill(image: np.ndarray, polygon: np.ndarray, colour: np.ndarray) -> None:
    import cv2

    mask = np.zeros(image.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, np.round(polygon).astype(np.int32), 1)
    image[mask > 0] = colour[mask > 0] if colour.ndim == 3 else colour


def _scene(yaw: float, height: float, mirrored_sides: bool):
    R, t = _pose(40.0, 600.0)
    xy = _plane_points(R, t)
    plate = _checker(xy + 3.0)
    photo = plate.copy()
    params = np.array([0.0, 0.0, yaw, np.log(90.0), np.log(55.0), np.log(height)])
    corners = box_corners(params)
    px = project(corners, K, R, t)
    if mirrored_sides:
        import cv2

        # the box's silhouette under its top shows the support reflected (x mirrored, shifted)
        reflected = _checker(xy * np.array([-1.0, 1.0]) + 11.0)
        hull = cv2.convexHull(px.astype(np.float32)).reshape(-1, 2)
        _fill(photo, hull, reflected)
    _fill(photo, px[4:], np.full(photo.shape, 235, np.uint8))
    return photo, plate, px[4:], R, t


def _low_fit(top_px: np.ndarray, height: float, R: np.ndarray, t: np.ndarray) -> OutlineFit:
    """The box the outline gives where only the top was found: that top, standing `height`."""
    params = _box_under(top_px, height, K, R, t)[0]
    return OutlineFit(params=params, cov=np.eye(6) * 1e-6, residual_px=0.5, outline_px=400)


@pytest.mark.parametrize("yaw", [0.2, 0.9, 1.4])
def test_sides_mirroring_the_support_give_the_height(yaw):
    photo, plate, top_px, R, t = _scene(yaw, 40.0, mirrored_sides=True)
    fit = _low_fit(top_px, 4.0, R, t)
    reading = read_hidden_sides(photo, plate, np.eye(3), IDENTITY_TONE, 0.25, fit, K, R, t)
    assert reading is not None and evidence_enough(reading)
    assert reading.height_mm == pytest.approx(40.0, rel=0.1)
    assert reading.low_mm <= 40.0 <= reading.high_mm
    # the footprint under the top at that height is the box's
    assert sorted([reading.length_mm, reading.width_mm]) == pytest.approx([55.0, 90.0], rel=0.1)


@pytest.mark.parametrize("yaw", [0.2, 0.9])
def test_a_box_as_low_as_its_outline_is_not_grown(yaw):
    # A truly low box: under its top the support's pattern shows unchanged.
    photo, plate, top_px, R, t = _scene(yaw, 6.0, mirrored_sides=False)
    fit = _low_fit(top_px, 6.0, R, t)
    reading = read_hidden_sides(photo, plate, np.eye(3), IDENTITY_TONE, 0.25, fit, K, R, t)
    assert reading is None or not evidence_enough(reading) or reading.height_mm < 1.1 * 6.0 + 1.0


def test_the_reading_adopted_or_taken_as_a_rival():
    photo, plate, top_px, R, t = _scene(0.5, 40.0, mirrored_sides=True)
    fit = _low_fit(top_px, 4.0, R, t)
    reading = read_hidden_sides(photo, plate, np.eye(3), IDENTITY_TONE, 0.25, fit, K, R, t)
    assert reading is not None
    adopted, words = widened(fit, reading, adopt=True)
    assert adopted.height_mm == pytest.approx(reading.height_mm)
    assert "only the part's top was outlined" in words
    # its sigma spans the reading's own spread: half of it each way at least
    assert adopted.sigma_mm()[2] >= (reading.high_mm - reading.low_mm) / 2 - 1e-9
    kept, words = widened(fit, reading, adopt=False)
    assert np.array_equal(kept.params, fit.params)
    assert kept.ambiguity_mm[2] == pytest.approx(reading.height_mm - fit.height_mm)
    assert kept.sigma_mm()[2] >= (reading.height_mm - fit.height_mm) / 2 - 1e-9
    assert "may stand" in words


def _silhouette(mirrored: bool):
    from prismcore.station.segment import Silhouette

    return Silhouette(contour=np.zeros((4, 2)), mask=np.zeros((H, W), bool), contrast=60.0, area_px=1,
                      warnings=[], difference=np.zeros((2, 2), np.float32), tone=IDENTITY_TONE,
                      shadow_least=0.25, mirrored=mirrored)


def _registration():
    from prismcore.station.calibrate import PlanePose
    from prismcore.station.registration import Registration

    pose = PlanePose(rvec=[0.0, 0.0, 0.0], tvec=[0.0, 0.0, 600.0], rms_px=0.1, corners=20)
    return Registration(pose, np.eye(3), 0.0, "unmoved")


def test_the_measurement_takes_the_reading_only_where_the_outline_is_suspect():
    from prismcore.station.measure import _hidden_sides

    photo, plate, top_px, R, t = _scene(0.5, 40.0, mirrored_sides=True)
    reg = _registration()
    # no height from the outline: the reading is the measurement
    flat = _low_fit(top_px, 0.5, R, t)
    adopted, words = _hidden_sides(photo, plate, reg, _silhouette(False), flat, K, R, t)
    assert adopted.height_mm == pytest.approx(40.0, rel=0.1) and "only the part's top" in words
    # a height the outline gave, part of the outline found where the pattern broke: a rival
    low = _low_fit(top_px, 10.0, R, t)
    kept, words = _hidden_sides(photo, plate, reg, _silhouette(True), low, K, R, t)
    assert np.array_equal(kept.params, low.params) and "may stand" in words
    # nothing suspect about the outline: untouched
    same, words = _hidden_sides(photo, plate, reg, _silhouette(False), low, K, R, t)
    assert same is low and words == ""
    # a fit with no finite size is left to be refused as degenerate, not read
    for bad in (np.nan, 800.0):
        broken = OutlineFit(params=np.array([0.0, 0.0, 0.5, np.log(90.0), bad, np.log(1.0)]),
                            cov=np.eye(6), residual_px=0.5, outline_px=400)
        with np.errstate(over="ignore", invalid="ignore"):
            assert _hidden_sides(photo, plate, reg, _silhouette(True), broken, K, R, t) == (broken, "")
            assert read_hidden_sides(photo, plate, np.eye(3), IDENTITY_TONE, 0.25, broken, K, R, t) is None


def test_a_top_with_no_height_under_it_is_a_box_of_log_height_minus_infinity_unwarned() -> None:
    """The heights tried start at the fit's own, which is 0 for a fit that gave none: that box's
    log height is -inf (as the fit's), with no "divide by zero" warning (warnings are errors
    here)."""
    R, t = _pose(45.0, 800.0)
    top_px = project(box_corners(np.array([0.0, 0.0, 0.3, np.log(80.0), np.log(50.0), np.log(1e-9)]))[4:],
                     K, R, t)
    params, corners = _box_under(top_px, 0.0, K, R, t)
    assert params[5] == -np.inf and np.all(np.isfinite(params[:5]))
    assert np.allclose(corners[:4], corners[4:], atol=1e-6)  # the footprint is the top

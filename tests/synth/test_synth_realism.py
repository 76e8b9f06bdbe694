"""The renderer's opt-in realism does what it says, checked against independent oracles:
OpenCV's own projection for the lens, a closed-form tangent for rounded silhouettes, Pillow's
EXIF reader for the JPEG, and the photo-like scene generator's promised ranges."""

from __future__ import annotations

import io
import math

import cv2
import numpy as np
import pytest
from PIL import Image

from prismcore.camera import CameraModel, undistort_points
from prismcore.errors import InputError
from prismsynth import (
    Box,
    CameraExif,
    Realism,
    Scene,
    Style,
    photo_like_scene,
    render_front_view,
    render_oblique_view,
)

SMALL = (640, 480)
CLEAN = Style(label=False, texture=0.0, lighting=0.0, noise_sigma=0.0, blur_sigma=0.0, jpeg_quality=None,
              clutter=False, box_color=(200, 60, 40))
BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def _world(box: Box) -> np.ndarray:
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    return np.array([(0, 0, 0), (W, 0, 0), (W, H, 0), (W, 0, 0), (W, 0, D), (0, H, 0), (W, H, D)], float)


def _opencv_project(scene: Scene, X: np.ndarray, dist: np.ndarray | None) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(scene.rotation)
    pts, _ = cv2.projectPoints(np.asarray(X, np.float64).reshape(-1, 1, 3), rvec, scene.translation,
                               scene.camera_matrix, dist)
    return pts.reshape(-1, 2)


def _camera(scene: Scene) -> CameraModel:
    K = scene.camera_matrix
    h, w = scene.image.shape[:2]
    assert scene.distortion is not None
    return CameraModel(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], dist=scene.distortion.tolist(),
                       image_width=w, image_height=h)


# ---------------------------------------------------------------- lens distortion


@pytest.mark.parametrize("k1,k2", [(-0.15, 0.0), (-0.15, 0.03), (-0.05, -0.02), (0.1, 0.0), (0.1, 0.02)])
@pytest.mark.parametrize("focal", [0.7 * SMALL[0], 1.2 * SMALL[0]])
def test_distorted_corners_are_opencvs_forward_model_and_undistort_to_the_pinhole(k1, k2, focal):
    scene = render_oblique_view(BOX, image_size=SMALL, focal_px=focal, yaw_deg=40.0, pitch_deg=20.0,
                                style=CLEAN, seed=1, realism=Realism(k1=k1, k2=k2))
    dist = np.array([k1, k2, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(scene.distortion, dist)
    pinhole = _opencv_project(scene, _world(BOX), None)
    seen = _opencv_project(scene, _world(BOX), dist)
    assert scene.pinhole_points is not None
    for name, ideal, lens in zip(NAMES, pinhole, seen, strict=True):
        np.testing.assert_allclose(scene.pinhole_points[name], ideal, atol=1e-9)
        np.testing.assert_allclose(scene.points[name], lens, atol=1e-6)
    moved = np.abs(seen - pinhole).max()
    assert moved > 1.0  # the lens really moves the corners: the oracle below can fail
    back = undistort_points(np.array([scene.points[n] for n in NAMES]), _camera(scene))
    np.testing.assert_allclose(back, pinhole, atol=0.05)


def _edge_x_at_row(scene: Scene, dist: np.ndarray, a: np.ndarray, b: np.ndarray, row: float) -> float:
    """Column where the distorted image of the 3-D segment a-b crosses `row` (bisection)."""
    lo, hi = 0.0, 1.0
    y_lo = _opencv_project(scene, [a], dist)[0, 1]
    for _ in range(60):
        mid = (lo + hi) / 2
        y_mid = _opencv_project(scene, [a + mid * (b - a)], dist)[0, 1]
        if (y_mid - row) * (y_lo - row) > 0:
            lo, y_lo = mid, y_mid
        else:
            hi = mid
    return float(_opencv_project(scene, [a + lo * (b - a)], dist)[0, 0])


@pytest.mark.parametrize("k1", [-0.15, 0.1])
def test_the_pixels_follow_the_lens(k1):
    # The front face's left edge (a silhouette) crosses 50% where OpenCV's model puts it, not
    # where the pinhole does.
    scene = render_oblique_view(BOX, image_size=SMALL, focal_px=0.7 * SMALL[0], distance_mm=150.0,
                                yaw_deg=35.0, pitch_deg=15.0, style=CLEAN, seed=2, realism=Realism(k1=k1))
    dist = np.array([k1, 0.0, 0.0, 0.0, 0.0])
    img = scene.image.astype(float)
    a, b = np.array([0.0, 0.0, 0.0]), np.array([0.0, BOX.height_mm, 0.0])
    p1, p6 = scene.points["p1"], scene.points["p6"]
    inside = np.round(np.mean([scene.points[n] for n in ("p1", "p3")], axis=0)).astype(int)
    face, bg = img[inside[1], inside[0]], img[3, 3]
    ch = int(np.argmax(np.abs(face - bg)))
    moved = []
    for frac in (0.1, 0.5, 0.9):
        row = round(p1[1] + frac * (p6[1] - p1[1]))
        truth = _edge_x_at_row(scene, dist, a, b, row)
        moved.append(abs(truth - _edge_x_at_row(scene, np.zeros(5), a, b, row)))
        start = math.floor(truth) - 6
        c = (img[row, start:start + 13, ch] - bg[ch]) / (face[ch] - bg[ch])
        k = int(np.nonzero(c >= 0.5)[0][0])
        half = start + k - 1 + (0.5 - c[k - 1]) / (c[k] - c[k - 1])
        assert abs(half - truth) < 0.15, (row, half, truth)
    assert max(moved) > 1.0  # where the pinhole puts the edge is clearly off: the test can fail


def test_a_distortion_that_folds_the_picture_is_refused():
    with pytest.raises(InputError, match="not invertible"):
        render_oblique_view(BOX, image_size=SMALL, focal_px=300.0, style=CLEAN, realism=Realism(k1=-0.6))


# ---------------------------------------------------------------- vignetting


@pytest.mark.parametrize("amount", [0.1, 0.25, 0.5])
def test_vignetting_darkens_the_corners_by_the_amount_and_not_the_centre(amount):
    plain = render_front_view(BOX, image_size=SMALL, style=CLEAN, seed=3, realism=Realism())
    dark = render_front_view(BOX, image_size=SMALL, style=CLEAN, seed=3, realism=Realism(vignetting=amount))
    a, b = plain.image.astype(float), dark.image.astype(float)
    w, h = SMALL
    for x, y in ((0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)):
        # Both are rounded to whole levels: |rint(x g) - rint(x) g| <= (1 + g) / 2.
        np.testing.assert_allclose(b[y, x], a[y, x] * (1 - amount), atol=1.0)
    # Everywhere: 1 - amount * (distance from the centre / the corners' distance)^2.
    ys, xs = np.mgrid[0:h, 0:w]
    cx, cy = (w - 1) / 2, (h - 1) / 2
    gain = 1 - amount * ((xs - cx) ** 2 + (ys - cy) ** 2) / (cx * cx + cy * cy)
    assert np.abs(b - a * gain[..., None]).max() <= 1.0
    centre = (round(cy), round(cx))
    assert abs(b[centre] - a[centre]).max() <= 1


# ---------------------------------------------------------------- JPEG and EXIF


def _exif(data: bytes) -> tuple[dict, dict]:
    with Image.open(io.BytesIO(data)) as im:
        exif = im.getexif()
        return dict(exif), dict(exif.get_ifd(0x8769))


@pytest.mark.parametrize("focal,quality", [(448.0, 92), (700.0, 75), (800.0, 40)])
def test_jpeg_bytes_decode_to_the_image_and_carry_the_exif(focal, quality):
    style = Style(**{**CLEAN.__dict__, "jpeg_quality": quality, "label": True, "texture": 6.0})
    raw = render_oblique_view(BOX, image_size=SMALL, focal_px=focal, style=Style(**{**style.__dict__,
                              "jpeg_quality": None}), seed=4, realism=Realism(k1=-0.05))
    scene = render_oblique_view(BOX, image_size=SMALL, focal_px=focal, style=style, seed=4,
                                realism=Realism(k1=-0.05, exif=CameraExif("Acme", "X-1")))
    assert raw.jpeg is None and scene.jpeg is not None and scene.jpeg[:2] == b"\xff\xd8"
    with Image.open(io.BytesIO(scene.jpeg)) as im:
        assert im.format == "JPEG"
        np.testing.assert_array_equal(np.asarray(im.convert("RGB")), scene.image)
    diff = np.abs(scene.image.astype(float) - raw.image).mean()
    assert 0 < diff < (2.0 if quality > 90 else 4.0)
    top, sub = _exif(scene.jpeg)
    assert top[0x010F] == "Acme" and top[0x0110] == "X-1"
    assert sub[0xA002] == SMALL[0] and sub[0xA003] == SMALL[1]
    diagonal_mm, diagonal_px = math.hypot(36.0, 24.0), math.hypot(*SMALL)
    assert sub[0xA405] == round(focal / diagonal_px * diagonal_mm)


def test_lower_jpeg_quality_loses_more():
    def err(q: int) -> float:
        style = Style(**{**CLEAN.__dict__, "jpeg_quality": q, "label": True, "texture": 6.0})
        a = render_front_view(BOX, image_size=SMALL, style=style, seed=5, realism=Realism())
        b = render_front_view(BOX, image_size=SMALL, style=Style(**{**style.__dict__, "jpeg_quality": None}),
                              seed=5, realism=Realism())
        return float(np.abs(a.image.astype(float) - b.image).mean())

    assert err(30) > err(95) * 1.5


def test_without_exif_the_jpeg_has_no_focal_length():
    style = Style(**{**CLEAN.__dict__, "jpeg_quality": 90})
    scene = render_front_view(BOX, image_size=SMALL, style=style, seed=6, realism=Realism())
    assert scene.jpeg is not None
    top, sub = _exif(scene.jpeg)
    assert 0xA405 not in sub and 0x010F not in top


# ---------------------------------------------------------------- rounded edges


def _front_row_profile(scene: Scene, ch: int) -> tuple[np.ndarray, float, float]:
    (x0, y0), (x1, y1) = scene.points["p1"], scene.points["p3"]
    row = round((y0 + y1) / 2)
    return scene.image[row, :, ch].astype(float), x0, x1


@pytest.mark.parametrize("radius", [2.0, 4.0])
def test_rounded_edges_soften_the_silhouette_profile(radius):
    # Square-on front view: every edge of the front is a silhouette. The rounded strip turns
    # the face's normal toward the hidden face over r mm, so the face's brightness changes
    # over about r / (mm per px) pixels inside the outline instead of at once.
    style = Style(**{**CLEAN.__dict__, "box_color": (150, 150, 150)})
    sharp = render_front_view(BOX, image_size=SMALL, focal_px=800.0, style=style, seed=7, realism=Realism())
    soft = render_front_view(BOX, image_size=SMALL, focal_px=800.0, style=style, seed=7,
                             realism=Realism(edge_radius_mm=radius))
    assert sharp.mm_per_px is not None
    band_px = radius / sharp.mm_per_px
    for side in ("left", "right"):
        widths = []
        for scene in (sharp, soft):
            line, x0, x1 = _front_row_profile(scene, 0)
            interior = line[round((x0 + x1) / 2)]
            inward = np.arange(math.ceil(x0) + 1, round((x0 + x1) / 2)) if side == "left" else \
                np.arange(math.floor(x1) - 1, round((x0 + x1) / 2), -1)
            off = np.nonzero(np.abs(line[inward[:round(3 * band_px)]] - interior) > 2)[0]
            widths.append(int(off.max()) + 1 if off.size else 0)  # the band off the interior's level
        assert widths[0] <= 1, (side, widths)
        assert widths[1] >= 0.5 * band_px, (side, widths, band_px)


def _silhouette_offset_mm(camera_xz: np.ndarray, r: float) -> float:
    """Closed form, front face's left edge: the cylinder's axis is at (x, z) = (r, r); the
    camera's tangent to the circle (the outer one) meets the front plane z = 0 at x = s."""
    d = camera_xz - np.array([r, r])
    dist = float(np.linalg.norm(d))
    base = math.atan2(d[1], d[0])
    for sign in (1.0, -1.0):
        angle = base + sign * math.acos(r / dist)
        q = np.array([r, r]) + r * np.array([math.cos(angle), math.sin(angle)])
        if q[0] < r and q[1] < r:  # on the rounded quarter facing -x and -z
            lam = camera_xz[1] / (camera_xz[1] - q[1])
            return float(camera_xz[0] + lam * (q[0] - camera_xz[0]))
    raise AssertionError("no tangent on the rounded quarter")


@pytest.mark.parametrize("yaw", [45.0, 60.0])
def test_rounded_silhouette_lies_where_the_tangent_from_the_camera_puts_it(yaw):
    r = 8.0
    kw = {"image_size": SMALL, "focal_px": 600.0, "yaw_deg": yaw, "pitch_deg": 10.0, "style": CLEAN,
          "seed": 8}
    sharp = render_oblique_view(BOX, **kw, realism=Realism())
    soft = render_oblique_view(BOX, **kw, realism=Realism(edge_radius_mm=r))
    centre = -soft.rotation.T @ soft.translation
    s = _silhouette_offset_mm(centre[[0, 2]], r)
    assert 0.3 * r < s < r
    bg = soft.image[3, 3].astype(float)
    for y_mm in (0.3 * BOX.height_mm, 0.6 * BOX.height_mm):
        ends = _opencv_project(soft, [[0.0, y_mm, 0.0], [s, y_mm, 0.0]], None)
        row = round(ends[0, 1])
        # Columns of the sharp outline and of the rounded box's outline at this row (lines x = 0
        # and x = s of the front plane).
        xs = []
        for x_mm in (0.0, s):
            a = _opencv_project(soft, [[x_mm, 0.0, 0.0]], None)[0]
            b = _opencv_project(soft, [[x_mm, BOX.height_mm, 0.0]], None)[0]
            xs.append(a[0] + (row - a[1]) * (b[0] - a[0]) / (b[1] - a[1]))
        assert xs[1] - xs[0] > 3.0  # the outline moves several pixels: the checks below can fail
        gap = [x for x in range(math.ceil(xs[0] + 1), math.floor(xs[1] - 1) + 1)]
        assert gap
        for x in gap:  # between the two outlines: the box's for the sharp one, background here
            assert np.abs(soft.image[row, x] - bg).max() <= 1, (row, x, xs)
            assert np.abs(sharp.image[row, x] - bg).max() > 40
        assert np.abs(soft.image[row, math.ceil(xs[1] + 1.5)] - bg).max() > 40


def test_rounding_wider_than_the_box_is_refused():
    with pytest.raises(InputError, match="edge_radius_mm"):
        render_front_view(Box(100.0, 50.0, 20.0), image_size=SMALL, style=CLEAN,
                          realism=Realism(edge_radius_mm=10.0))


# ---------------------------------------------------------------- options and determinism


@pytest.mark.parametrize("kwargs,match", [({"vignetting": 1.0}, "vignetting"),
                                          ({"shot_noise": -1.0}, "shot_noise"),
                                          ({"edge_radius_mm": -0.5}, "edge_radius_mm"),
                                          ({"k1": float("nan")}, "k1")])
def test_bad_options_are_refused(kwargs, match):
    with pytest.raises(InputError, match=match):
        Realism(**kwargs)


def test_exif_needs_a_jpeg():
    with pytest.raises(InputError, match="jpeg_quality"):
        render_front_view(BOX, image_size=SMALL, style=CLEAN, realism=Realism(exif=CameraExif()))


def test_realistic_render_is_deterministic_by_seed():
    realism = Realism(k1=-0.1, edge_radius_mm=1.5, vignetting=0.2, shot_noise=4.0, exif=CameraExif())
    a, b, c = (render_oblique_view(BOX, image_size=SMALL, style=Style(), seed=s, realism=realism)
               for s in (9, 9, 10))
    assert a.jpeg == b.jpeg and a.points == b.points
    np.testing.assert_array_equal(a.image, b.image)
    assert a.jpeg != c.jpeg


# ---------------------------------------------------------------- photo-like scenes


@pytest.mark.parametrize("seed", range(6))
def test_photo_like_scenes_keep_their_promises(seed):
    p = photo_like_scene(seed, image_size=SMALL)
    w, h = SMALL
    K, dist = p.camera_matrix, p.distortion
    assert 0.7 * w <= K[0, 0] <= 1.2 * w and K[0, 0] == K[1, 1]
    assert -0.15 <= dist[0] <= 0.10 and np.all(dist[2:] == 0)
    # Face normals 20-60 degrees from the direction to the camera, recomputed from R and t.
    centre = -p.scene.rotation.T @ p.scene.translation
    B = p.box
    for face_centre, normal in (((B.width_mm / 2, B.height_mm / 2, 0), (0, 0, -1)),
                                ((B.width_mm, B.height_mm / 2, B.depth_mm / 2), (1, 0, 0))):
        v = centre - np.array(face_centre, float)
        angle = math.degrees(math.acos(np.dot(normal, v) / np.linalg.norm(v)))
        assert 20.0 <= angle <= 60.0
    # The points are OpenCV's distorted projections, inside the picture; clicks within 3 px.
    seen = _opencv_project(p.scene, _world(B), dist)
    np.testing.assert_allclose([p.scene.points[n] for n in NAMES], seen, atol=1e-6)
    assert np.all((seen >= 0) & (seen <= [w - 1, h - 1]))
    off = np.linalg.norm(np.array(p.click_list()) - seen, axis=1)
    assert off.max() <= 3.0 + 1e-9
    # The image is the JPEG; EXIF in even seeds only, with the focal length that was used.
    with Image.open(io.BytesIO(p.jpeg)) as im:
        np.testing.assert_array_equal(np.asarray(im.convert("RGB")), p.image)
    top, sub = _exif(p.jpeg)
    assert p.has_exif == (seed % 2 == 0) == (0xA405 in sub)
    if p.has_exif:
        assert sub[0xA405] == round(K[0, 0] / math.hypot(w, h) * math.hypot(36, 24))
        assert top[0x010F] and top[0x0110]
    assert p.known_edge in ("width", "height", "depth")
    assert p.known_length_mm == getattr(B, f"{p.known_edge}_mm")


def test_photo_like_scenes_vary_and_repeat():
    a, b, c = photo_like_scene(3, image_size=SMALL), photo_like_scene(3, image_size=SMALL), \
        photo_like_scene(4, image_size=SMALL)
    assert a.jpeg == b.jpeg and a.clicks == b.clicks and a.box == b.box
    assert a.box != c.box and a.jpeg != c.jpeg
    # Over a run of seeds the ranges are used, not one corner of them.
    runs = [photo_like_scene(s, image_size=SMALL) for s in range(5, 11)]
    assert len({r.distortion[0] for r in runs}) == len(runs)
    offsets = [np.linalg.norm(np.subtract(r.clicks["p1"], r.scene.points["p1"])) for r in runs]
    assert max(offsets) > 1.5

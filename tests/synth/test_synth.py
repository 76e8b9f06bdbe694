"""The synthetic renderer is ground truth: its points, scale and edges must be exact."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from PIL import Image

from prismsynth import (
    Box,
    Scene,
    Style,
    render_front_view,
    render_oblique_view,
    render_side_view,
    save_image,
)

SMALL = (640, 512)
CLEAN = Style(label=False, texture=0.0, lighting=0.0, noise_sigma=0.0, blur_sigma=0.0, jpeg_quality=None,
              clutter=False, box_color=(200, 60, 40))
BOXES = [Box(120.0, 80.0, 60.0), Box(90.0, 140.0, 45.0)]


# ---------------------------------------------------------------- an independent camera model


def _intrinsics(focal: float, size: tuple[int, int]) -> np.ndarray:
    return np.array([[focal, 0, (size[0] - 1) / 2], [0, focal, (size[1] - 1) / 2], [0, 0, 1.0]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _pose(view: str, box: Box, focal: float, dist: float, offset=(0.0, 0.0), yaw=30.0, pitch=15.0):
    """World-to-camera (R, t) from the documented geometry, built without the module's code."""
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    if view == "oblique":
        # Camera-to-world: turn a camera looking along +Z by -yaw about Y, then tilt it down.
        cam_to_world = _rot_y(-math.radians(yaw)) @ _rot_x(-math.radians(pitch))
        R = cam_to_world.T
        centre = np.array([W / 2, H / 2, 0.0]) - dist * cam_to_world[:, 2]
        return R, -R @ centre
    if view == "front":
        R, face_centre = np.eye(3), np.array([W / 2, H / 2, 0.0])
    else:  # rows: camera x = world +Z, camera y = world +Y, camera z = world -X
        R, face_centre = np.array([[0, 0, 1.0], [0, 1, 0], [-1, 0, 0]]), np.array([W, H / 2, D / 2])
    wanted = np.array([offset[0] * dist / focal, offset[1] * dist / focal, dist])
    return R, wanted - R @ face_centre


def _world_points(box: Box, view: str) -> dict[str, tuple[float, float, float]]:
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    every = {"p1": (0, 0, 0), "p2": (W, 0, 0), "p3": (W, H, 0), "p4": (W, 0, 0), "p5": (W, 0, D),
             "p6": (0, H, 0), "p7": (W, H, D)}
    names = {"front": ("p1", "p2", "p3", "p6"), "side": ("p3", "p4", "p5", "p7"),
             "oblique": tuple(every)}[view]
    return {n: every[n] for n in names}


def _project(K, R, t, X) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(np.asarray(R, np.float64))
    pts, _ = cv2.projectPoints(np.asarray(X, np.float64).reshape(-1, 1, 3), rvec,
                               np.asarray(t, np.float64), K, None)
    return pts.reshape(-1, 2)


def _render(view: str, box: Box, **kw) -> Scene:
    if view == "oblique":
        kw.pop("offset_px", None)
        return render_oblique_view(box, **kw)
    return (render_front_view if view == "front" else render_side_view)(box, **kw)


# ---------------------------------------------------------------- edge measurement on the image


def _crossings(profile: np.ndarray, outside: float, inside: float, start: int) -> tuple[float, float]:
    """50%-crossing (linear interpolation) and area-based position of a step in a 1-D profile.

    `profile` runs from outside the face (at index 0, pixel coordinate `start`) to inside.
    """
    c = (profile.astype(np.float64) - outside) / (inside - outside)
    k = int(np.nonzero(c >= 0.5)[0][0])
    half = start + k - 1 + (0.5 - c[k - 1]) / (c[k] - c[k - 1])
    area = start + len(c) - 0.5 - float(np.sum(np.clip(c, 0, 1)))
    return half, area


def _edge_positions(image: np.ndarray, edge: str, at: int, lo: float, hi: float, channel: int,
                    face_level: float, background: float, span: int = 12) -> tuple[float, float]:
    """Measure a face edge expected near `lo` (left/top) or `hi` (right/bottom) along row or
    column `at`; returns (50% crossing, area-based position) in image coordinates."""
    line = image[at, :, channel] if edge in ("left", "right") else image[:, at, channel]
    if edge in ("left", "top"):
        start = round(lo) - span
        return _crossings(line[start:start + 2 * span + 1], background, face_level, start)
    start = round(hi) - span
    seg = line[start:start + 2 * span + 1][::-1]  # from outside (far end) inward
    half, area = _crossings(seg, background, face_level, 0)
    end = start + 2 * span  # reversed index i is pixel end - i
    return end - half, end - area


OFFSETS = [(0.0, 0.0), (0.3, -0.27), (-0.45, 0.15), (0.25, 0.5), (0.123, -0.377)]


@pytest.mark.parametrize("view", ["front", "side"])
@pytest.mark.parametrize("offset", OFFSETS, ids=str)
def test_square_view_edges_cross_half_intensity_at_projected_edges(view, offset):
    box = BOXES[0]
    scene = _render(view, box, image_size=SMALL, focal_px=900.0, offset_px=offset, style=CLEAN, seed=3)
    img = scene.image
    pts = scene.points
    tl, br = (pts["p1"], pts["p3"]) if view == "front" else (pts["p4"], pts["p7"])
    (x0, y0), (x1, y1) = tl, br
    cx, cy = round((x0 + x1) / 2), round((y0 + y1) / 2)
    face = img[cy - 5:cy + 6, cx - 5:cx + 6].reshape(-1, 3).astype(float)
    bg = img[2:8, 2:8].reshape(-1, 3).astype(float)
    assert np.ptp(face, axis=0).max() == 0 and np.ptp(bg, axis=0).max() == 0  # uniform, as set
    channel = int(np.argmax(np.abs(face[0] - bg[0])))
    assert abs(face[0, channel] - bg[0, channel]) > 40
    for edge, lo, hi, rows in (("left", x0, x1, (cy - 20, cy, cy + 17)),
                               ("right", x0, x1, (cy - 20, cy, cy + 17)),
                               ("top", y0, y1, (cx - 30, cx, cx + 23)),
                               ("bottom", y0, y1, (cx - 30, cx, cx + 23))):
        truth = lo if edge in ("left", "top") else hi
        for at in rows:
            half, area = _edge_positions(img, edge, at, lo, hi, channel, face[0, channel], bg[0, channel])
            assert abs(half - truth) < 0.1, (edge, at, half, truth)
            assert abs(area - truth) < 0.02, (edge, at, area, truth)


@pytest.mark.parametrize("yaw,pitch", [(30.0, 15.0), (40.0, 20.0)])
def test_oblique_edges_cross_half_intensity_at_projected_edges(yaw, pitch):
    # Slanted edges: along a row the left edge p1-p6 sits where the line through them is.
    scene = render_oblique_view(BOXES[0], image_size=SMALL, focal_px=900.0, yaw_deg=yaw,
                                pitch_deg=pitch, style=CLEAN, seed=2)
    img = scene.image
    p1, p6, p3 = (np.array(scene.points[n]) for n in ("p1", "p6", "p3"))
    centre = np.round((p1 + p3) / 2).astype(int)
    face = img[centre[1], centre[0]].astype(float)
    bg = img[2, 2].astype(float)
    channel = int(np.argmax(np.abs(face - bg)))
    for y in (int(p1[1] + 0.3 * (p6[1] - p1[1])), int(p1[1] + 0.6 * (p6[1] - p1[1]))):
        truth = p1[0] + (y - p1[1]) * (p6[0] - p1[0]) / (p6[1] - p1[1])
        half, area = _edge_positions(img, "left", y, truth, truth, channel, face[channel], bg[channel])
        assert abs(half - truth) < 0.1 and abs(area - truth) < 0.05, (y, half, area, truth)
    for x in (int(p6[0] + 0.3 * (p3[0] - p6[0])), int(p6[0] + 0.7 * (p3[0] - p6[0]))):
        truth = p6[1] + (x - p6[0]) * (p3[1] - p6[1]) / (p3[0] - p6[0])
        half, area = _edge_positions(img, "bottom", x, truth, truth, channel, face[channel], bg[channel])
        assert abs(half - truth) < 0.1 and abs(area - truth) < 0.05, (x, half, area, truth)


# ---------------------------------------------------------------- points and scale


@pytest.mark.parametrize("view", ["front", "side", "oblique"])
@pytest.mark.parametrize("box", BOXES, ids=str)
@pytest.mark.parametrize("offset", [(0.0, 0.0), (37.25, -20.5)], ids=str)
def test_points_are_the_corners_projected_by_an_independent_camera(view, box, offset):
    kw = {"image_size": SMALL, "focal_px": 1000.0, "distance_mm": 400.0, "offset_px": offset,
          "style": CLEAN, "seed": 1}
    if view == "oblique":
        kw.update(yaw_deg=35.0, pitch_deg=12.0)
    scene = _render(view, box, **kw)
    K = _intrinsics(1000.0, SMALL)
    R, t = _pose(view, box, 1000.0, 400.0, offset, 35.0, 12.0)
    world = _world_points(box, view)
    expected = _project(K, R, t, list(world.values()))
    assert set(scene.points) == set(world)
    for name, xy in zip(world, expected, strict=True):
        np.testing.assert_allclose(scene.points[name], xy, atol=1e-9)
        assert scene.points[name.upper()] == scene.points[name]  # the paper's names work too
    np.testing.assert_allclose(scene.camera_matrix, K)
    np.testing.assert_allclose(scene.rotation, R, atol=1e-12)
    np.testing.assert_allclose(scene.translation, t, atol=1e-9)
    assert scene.view == view and scene.box == box and scene.focal_px == 1000.0
    assert scene.distance_mm == 400.0


def test_oblique_view_sees_front_side_and_top_from_the_right_and_above():
    box = BOXES[0]
    scene = render_oblique_view(box, image_size=SMALL, focal_px=900.0, style=CLEAN, seed=4)
    p = {n: np.array(v) for n, v in scene.points.items()}
    assert scene.mm_per_px is None and scene.view == "oblique"
    np.testing.assert_array_equal(p["p2"], p["p4"])
    assert p["p5"][0] > p["p2"][0] and p["p7"][0] > p["p3"][0]  # the side recedes to the right
    assert p["p5"][1] < p["p2"][1]  # the top recedes upward
    # The camera aims at the front face's centre, at distance_mm along the optical axis.
    centre_cam = scene.rotation @ np.array([box.width_mm / 2, box.height_mm / 2, 0]) + scene.translation
    np.testing.assert_allclose(centre_cam, [0, 0, scene.distance_mm], atol=1e-9)
    # Every box corner lies inside the picture.
    for xy in p.values():
        assert 0 <= xy[0] < SMALL[0] and 0 <= xy[1] < SMALL[1]
    # The three visible faces get different shades: their common edges have contrast.
    img = scene.image.astype(float)

    def mean_in(quad: list[str]) -> np.ndarray:
        c = np.mean([p[n] for n in quad], axis=0)
        return img[round(c[1]) - 2:round(c[1]) + 3, round(c[0]) - 2:round(c[0]) + 3].mean((0, 1))

    W, D = box.width_mm, box.depth_mm
    top_c = _project(scene.camera_matrix, scene.rotation, scene.translation, [(W / 2, 0, D / 2)])[0]
    top = img[round(top_c[1]), round(top_c[0])]
    front, side = mean_in(["p1", "p2", "p3", "p6"]), mean_in(["p4", "p5", "p7", "p3"])
    assert np.abs(front - side).max() > 15 and np.abs(front - top).max() > 10
    assert np.abs(side - top).max() > 10


@pytest.mark.parametrize("view", ["front", "side"])
@pytest.mark.parametrize("box", [*BOXES, Box(200.0, 60.0, 110.0)], ids=str)
def test_square_views_scale_is_distance_over_focal(view, box):
    scene = _render(view, box, image_size=SMALL, focal_px=800.0, offset_px=(3.3, -7.8), style=CLEAN, seed=5)
    assert scene.mm_per_px == pytest.approx(scene.distance_mm / scene.focal_px, rel=1e-12)
    face_w = box.width_mm if view == "front" else box.depth_mm
    tl, tr, br = (scene.points[n] for n in (("p1", "p2", "p3") if view == "front" else ("p4", "p5", "p7")))
    assert tr[0] - tl[0] == pytest.approx(face_w / scene.mm_per_px, abs=1e-9)
    assert br[1] - tr[1] == pytest.approx(box.height_mm / scene.mm_per_px, abs=1e-9)
    assert tr[1] == pytest.approx(tl[1], abs=1e-9) and br[0] == pytest.approx(tr[0], abs=1e-9)
    # The automatic distance frames the face: about half the width or 3/4 of the height.
    fill_w, fill_h = (tr[0] - tl[0]) / SMALL[0], (br[1] - tr[1]) / SMALL[1]
    assert fill_w == pytest.approx(0.5) or fill_h == pytest.approx(0.75)
    assert fill_w <= 0.5 + 1e-9 and fill_h <= 0.75 + 1e-9
    # And the face measured on the image (area-based edges) has that size.
    img = scene.image
    cx, cy = round((tl[0] + tr[0]) / 2), round((tr[1] + br[1]) / 2)
    face, bg = img[cy, cx].astype(float), img[1, 1].astype(float)
    ch = int(np.argmax(np.abs(face - bg)))
    left = _edge_positions(img, "left", cy, tl[0], tr[0], ch, face[ch], bg[ch])[1]
    right = _edge_positions(img, "right", cy, tl[0], tr[0], ch, face[ch], bg[ch])[1]
    top = _edge_positions(img, "top", cx, tr[1], br[1], ch, face[ch], bg[ch])[1]
    bottom = _edge_positions(img, "bottom", cx, tr[1], br[1], ch, face[ch], bg[ch])[1]
    assert right - left == pytest.approx(face_w / scene.mm_per_px, abs=0.2)
    assert bottom - top == pytest.approx(box.height_mm / scene.mm_per_px, abs=0.2)


def test_oblique_auto_distance_frames_the_box():
    scene = render_oblique_view(BOXES[1], image_size=SMALL, yaw_deg=40.0, pitch_deg=20.0, style=CLEAN)
    verts = [(x, y, z) for x in (0, 90.0) for y in (0, 140.0) for z in (0, 45.0)]
    xy = _project(scene.camera_matrix, scene.rotation, scene.translation, verts)
    assert np.ptp(xy[:, 0]) / SMALL[0] == pytest.approx(0.5, abs=1e-6) or \
        np.ptp(xy[:, 1]) / SMALL[1] == pytest.approx(0.75, abs=1e-6)
    assert np.ptp(xy[:, 0]) / SMALL[0] <= 0.5 + 1e-6 and np.ptp(xy[:, 1]) / SMALL[1] <= 0.75 + 1e-6


# ---------------------------------------------------------------- style, determinism, output


@pytest.mark.parametrize("view", ["front", "side", "oblique"])
@pytest.mark.parametrize("style", [Style(), Style(background_close=True, jpeg_quality=None), CLEAN],
                         ids=["default", "close", "clean"])
def test_image_is_rgb_uint8_and_deterministic_by_seed(view, style):
    a = _render(view, BOXES[0], image_size=SMALL, style=style, seed=11)
    b = _render(view, BOXES[0], image_size=SMALL, style=style, seed=11)
    c = _render(view, BOXES[0], image_size=SMALL, style=style, seed=12)
    assert a.image.dtype == np.uint8 and a.image.shape == (SMALL[1], SMALL[0], 3)
    np.testing.assert_array_equal(a.image, b.image)
    assert a.points == b.points
    assert not np.array_equal(a.image, c.image)


def test_full_size_default_scene():
    scene = render_oblique_view(Box(120.0, 80.0, 60.0), seed=1)
    assert scene.image.shape == (1024, 1280, 3) and scene.image.dtype == np.uint8
    assert set(scene.points) == {"p1", "p2", "p3", "p4", "p5", "p6", "p7"}


def _front_and_background(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    (x0, y0), (x1, y1) = scene.points["p1"], scene.points["p3"]
    img = scene.image.astype(float)
    mask = np.ones(img.shape[:2], bool)
    mask[max(0, int(y0) - 40):int(y1) + 40, max(0, int(x0) - 40):int(x1) + 40] = False
    face = img[int(y0) + 3:int(y1) - 2, int(x0) + 3:int(x1) - 2]
    return np.median(face.reshape(-1, 3), axis=0), np.median(img[mask], axis=0)


@pytest.mark.parametrize("seed", range(3))
def test_close_background_is_near_the_front_face_colour(seed):
    quiet = Style(label=False, texture=0.0, lighting=0.0, clutter=False, background_close=True)
    face, bg = _front_and_background(render_front_view(BOXES[0], image_size=SMALL, style=quiet, seed=seed))
    assert np.linalg.norm(face - bg) <= 20
    face, bg = _front_and_background(render_front_view(BOXES[0], image_size=SMALL,
                                                       style=Style(background_close=True), seed=seed))
    assert np.linalg.norm(face - bg) <= 35  # clutter, grain, lighting and shadow included
    face, bg = _front_and_background(render_front_view(BOXES[0], image_size=SMALL, style=Style(), seed=seed))
    assert np.linalg.norm(face - bg) > 35


@pytest.mark.parametrize("view", ["front", "side"])
@pytest.mark.parametrize("seed", range(4))
def test_label_is_inset_from_the_face_edges(view, seed):
    style = Style(label=True, texture=0.0, lighting=0.0, noise_sigma=0.0, blur_sigma=0.0,
                  jpeg_quality=None, clutter=False)
    scene = _render(view, BOXES[seed % 2], image_size=SMALL, style=style, seed=seed)
    (x0, y0), (x1, y1) = scene.points["p1" if view == "front" else "p4"], scene.points["p3" if view ==
                                                                                         "front" else "p7"]
    img = scene.image.astype(int)
    face = img[int(y0) + 2:int(y1) - 1, int(x0) + 2:int(x1) - 1]
    h, w = face.shape[:2]
    band = np.ones((h, w), bool)
    band[int(0.11 * h):h - int(0.11 * h), int(0.11 * w):w - int(0.11 * w)] = False
    plain = face[band]
    assert np.ptp(plain, axis=0).max() <= 1  # nothing printed near the edges
    assert np.ptp(face.reshape(-1, 3), axis=0).max() > 40  # but a label inside


def test_textured_faces_and_noise_change_pixels():
    base = Style(label=False, texture=0.0, lighting=0.0, noise_sigma=0.0, blur_sigma=0.0,
                 jpeg_quality=None, clutter=False)
    flat = render_front_view(BOXES[0], image_size=SMALL, style=base, seed=9)
    (x0, y0), (x1, y1) = flat.points["p1"], flat.points["p3"]
    region = (slice(int(y0) + 5, int(y1) - 5), slice(int(x0) + 5, int(x1) - 5))
    assert flat.image[region].reshape(-1, 3).std(axis=0).max() == 0
    for change in ({"texture": 6.0}, {"lighting": 0.25}, {"noise_sigma": 2.0}, {"jpeg_quality": 50}):
        scene = render_front_view(BOXES[0], image_size=SMALL, style=Style(**{**base.__dict__, **change}),
                                  seed=9)
        assert scene.image[region].reshape(-1, 3).std(axis=0).max() > 0.5, change


@pytest.mark.parametrize("ext", [".png", ".bmp", ".tif", ".webp", ".jpg"])
def test_save_image_by_extension(tmp_path, ext):
    scene = render_front_view(BOXES[0], image_size=(96, 64), seed=0)
    path = tmp_path / f"box{ext}"
    save_image(scene, path)
    back = np.asarray(Image.open(path).convert("RGB"))
    assert back.shape == scene.image.shape
    if ext == ".jpg":
        assert np.abs(back.astype(int) - scene.image).mean() < 4
    else:
        np.testing.assert_array_equal(back, scene.image)
    save_image(scene.image, tmp_path / f"array{ext}")  # a bare array is accepted too


def test_bad_inputs_are_refused(tmp_path):
    with pytest.raises(ValueError, match="extension"):
        save_image(np.zeros((4, 4, 3), np.uint8), tmp_path / "x.gif")
    with pytest.raises(ValueError, match="uint8"):
        save_image(np.zeros((4, 4), np.float32), tmp_path / "x.png")
    with pytest.raises(ValueError, match="width_mm"):
        Box(0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="jpeg_quality"):
        Style(jpeg_quality=0)
    with pytest.raises(ValueError, match="behind the camera"):
        render_oblique_view(BOXES[0], distance_mm=10.0, image_size=SMALL)

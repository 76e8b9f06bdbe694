"""Cluttered photos of one box for the zero-click search: random size, pose, light and objects.

Each scene is `render.render_oblique_view` (cluttered background, labels, texture, lighting)
rendered without its JPEG step, with a few solid objects standing beside the box (outside its
silhouette, so they never hide a corner), then JPEG-encoded. The truth is every box corner the
camera sees, so a search may label the faces its own way (which face is the front) and still be
checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .models import Box, Scene, Style
from .render import render_oblique_view

__all__ = ["ClutterScene", "box_vertices_px", "clutter_scene"]

_IMAGE_SIZE = (1280, 1024)


@dataclass(frozen=True, eq=False)
class ClutterScene:
    """A rendered photo of one box among other objects, and its truth.

    Attributes
    ----------
    image : np.ndarray
        (H, W, 3) uint8 RGB, after the JPEG round trip.
    scene : Scene
        The box's render (its `points` are p1..p7 with the scene's `side_face`).
    vertices : np.ndarray
        (8, 3) float64 world corners of the box, mm (x, y, z in 0/W, 0/H, 0/D).
    vertices_px : np.ndarray
        (8, 2) float64 image positions of `vertices`, px.
    visible : np.ndarray
        (8,) bool: the corner lies on a face the camera sees.
    faces_visible : int
        2 or 3.
    box_largest : bool
        No clutter object covers more of the image than the box's silhouette.
    background_close : bool
        The background's colour is within about 20 RGB of the front face's.
    objects : int
        Number of solid clutter objects drawn.
    """

    image: np.ndarray
    scene: Scene
    vertices: np.ndarray
    vertices_px: np.ndarray
    visible: np.ndarray
    faces_visible: int
    box_largest: bool
    background_close: bool
    objects: int


def box_vertices_px(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box's 8 corners (world mm), their image positions (px) and whether the camera sees them.

    Returns
    -------
    vertices : (8, 3) float64, vertices_px : (8, 2) float64, visible : (8,) bool
    """
    b = scene.box
    verts = np.array([[x, y, z] for x in (0, b.width_mm) for y in (0, b.height_mm)
                      for z in (0, b.depth_mm)], dtype=np.float64)
    cam = verts @ scene.rotation.T + scene.translation
    uvw = cam @ scene.camera_matrix.T
    px = uvw[:, :2] / uvw[:, 2:3]
    centre = -scene.rotation.T @ scene.translation
    size = np.array([b.width_mm, b.height_mm, b.depth_mm])
    visible = np.zeros(8, dtype=bool)
    for axis in range(3):
        for side, value in ((0, 0.0), (1, size[axis])):
            sees = centre[axis] < value if side == 0 else centre[axis] > value
            if sees:
                visible |= np.isclose(verts[:, axis], value)
    return verts, px, visible


def _silhouette(px: np.ndarray, visible: np.ndarray) -> np.ndarray:
    return cv2.convexHull(px.astype(np.float32)).reshape(-1, 2)


def _objects(rng: np.random.Generator, img: np.ndarray, hull: np.ndarray, box_area: float
             ) -> tuple[int, float]:
    """Draw 1-5 solid objects (cards, discs, blobs) that do not touch the box's silhouette.

    Returns how many were drawn and the largest one's area, px^2.
    """
    h, w = img.shape[:2]
    keep_out = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(keep_out, np.round(hull).astype(np.int32), 255)
    keep_out = np.asarray(cv2.dilate(keep_out, np.ones((41, 41), np.uint8)), dtype=np.uint8)
    drawn, largest = 0, 0.0
    for _ in range(int(rng.integers(1, 6))):
        for _attempt in range(20):
            mask = np.zeros((h, w), np.uint8)
            # Now and then an object larger than the box: the box is then not the largest thing.
            r = math.sqrt(box_area) * (rng.uniform(0.7, 1.0) if rng.random() < 0.12
                                       else rng.uniform(0.15, 0.45))
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
            kind = rng.integers(3)
            if kind == 0:
                rect = ((cx, cy), (r * rng.uniform(0.8, 1.6), r * rng.uniform(0.5, 1.0)),
                        rng.uniform(0, 180))
                cv2.fillConvexPoly(mask, np.round(cv2.boxPoints(rect)).astype(np.int32), 255, cv2.LINE_AA)
            elif kind == 1:
                cv2.ellipse(mask, (round(cx), round(cy)), (round(r * 0.6), round(r * rng.uniform(0.3, 0.6))),
                            rng.uniform(0, 180), 0, 360, 255, -1, cv2.LINE_AA)
            else:
                poly = np.array([cx, cy]) + rng.uniform(-r / 2, r / 2, (int(rng.integers(5, 8)), 2))
                cv2.fillConvexPoly(mask, cv2.convexHull(np.round(poly).astype(np.int32)), 255, cv2.LINE_AA)
            if (mask & keep_out).any() or not mask.any():
                continue
            colour = rng.uniform(20, 235, 3)
            shade = np.linspace(0.8, 1.1, w, dtype=np.float32)[None, :, None]
            alpha = (mask.astype(np.float32) / 255)[..., None]
            img[:] = np.clip(img * (1 - alpha) + colour * shade * alpha, 0, 255)
            drawn += 1
            largest = max(largest, float(mask.sum()) / 255)
            break
    return drawn, largest


def clutter_scene(seed: int, *, image_size: tuple[int, int] = _IMAGE_SIZE,
                  background_close: bool | None = None, faces: int | None = None,
                  objects: bool = True) -> ClutterScene:
    """One random scene: box size, pose (two or three faces), light, texture, labels, clutter, JPEG.

    Parameters
    ----------
    seed : int
        All randomness.
    image_size : (int, int)
        (width, height) px.
    background_close : bool or None
        Force the background colour close to the box's; None: in 20 % of the seeds.
    faces : {2, 3} or None
        Force two or three visible faces; None: three in 60 % of the seeds.
    objects : bool
        Draw the solid objects beside the box.
    """
    rng = np.random.default_rng(np.random.SeedSequence([12, int(seed)]))
    box = Box(*(float(v) for v in rng.uniform(50, 300, 3).round(1)))
    close = bool(rng.random() < 0.2) if background_close is None else background_close
    three = bool(rng.random() < 0.6) if faces is None else faces == 3
    side = rng.choice([-1.0, 1.0])
    if three:
        yaw, pitch = side * rng.uniform(20, 55), rng.uniform(15, 40)
    elif rng.random() < 0.8:  # front and a side, the top hidden: the camera below its plane
        yaw, pitch = side * rng.uniform(20, 55), 0.0
    else:  # front and top
        yaw, pitch = 0.0, rng.uniform(20, 50)
    focal = float(rng.uniform(1000, 2200))
    style = Style(label=bool(rng.random() < 0.85), texture=float(rng.uniform(2, 8)),
                  lighting=float(rng.uniform(0.05, 0.4)), noise_sigma=float(rng.uniform(1, 3)),
                  blur_sigma=float(rng.uniform(0.4, 0.9)), jpeg_quality=None, clutter=True,
                  background_close=close)
    # The automatic distance (the box spans half the width) scales with the picture: read it
    # from a tiny render, then move back now and then so the search cannot rely on the box's size.
    tiny = render_oblique_view(box, image_size=(image_size[0] // 16, image_size[1] // 16),
                               focal_px=focal / 16, yaw_deg=yaw, pitch_deg=pitch, style=Style(
                                   label=False, clutter=False, jpeg_quality=None), seed=0)
    distance = tiny.distance_mm * float(rng.uniform(1.0, 1.8))
    scene = render_oblique_view(box, image_size=image_size, focal_px=focal, yaw_deg=yaw,
                                pitch_deg=pitch, style=style, seed=int(seed), distance_mm=distance)
    verts, px, visible = box_vertices_px(scene)
    centre = -scene.rotation.T @ scene.translation
    size = np.array([box.width_mm, box.height_mm, box.depth_mm])
    n_faces = int(sum((centre[a] < 0) or (centre[a] > size[a]) for a in range(3)))
    img = scene.image.astype(np.float32)
    hull = _silhouette(px, visible)
    box_area = float(cv2.contourArea(hull.astype(np.float32)))
    drawn, largest = _objects(rng, img, hull, box_area) if objects else (0, 0.0)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    quality = int(rng.integers(75, 96))
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(out, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    image = np.asarray(cv2.cvtColor(np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)), cv2.COLOR_BGR2RGB),
                       dtype=np.uint8)
    return ClutterScene(image, scene, verts, px, visible, n_faces, largest <= box_area, close, drawn)


def empty_scene(seed: int, *, image_size: tuple[int, int] = _IMAGE_SIZE) -> np.ndarray:
    """(H, W, 3) uint8 RGB: a cluttered background (shapes, lines, text) and no box, JPEG'd."""
    from .phone import _jpeg_round_trip
    from .textures import _background

    rng = np.random.default_rng(np.random.SeedSequence([13, int(seed)]))
    style = Style()
    bg = _background(rng, image_size, style, rng.uniform(40, 215, 3))
    img = np.clip(np.rint(bg), 0, 255).astype(np.uint8)
    return _jpeg_round_trip(img, 90)


def two_box_scene(seed: int, *, image_size: tuple[int, int] = _IMAGE_SIZE
                  ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Two equal boxes side by side, the second the first's mirror image, on a plain background.

    The first box is photographed left of the image centre; the picture mirrored about its
    vertical centre line is another pinhole photo (of the mirrored world), so the right half
    shows an equal box, seen from the other side, through the same camera.

    Returns the (H, W, 3) uint8 RGB image and, per box, its (8, 2) corners in it (px).
    """
    from .box_geometry import _camera_matrix, _oblique_pose, _principal
    from .phone import _jpeg_round_trip
    from .render import _render

    w = image_size[0]
    box = Box(120.0, 90.0, 70.0)
    focal, distance = 0.8 * w, 600.0
    R, t = _oblique_pose(box, distance, 30.0, 25.0)
    t = t + np.array([-0.27 * w * distance / focal, 0.0, 0.0])  # the box left of the centre
    K = _camera_matrix(focal, _principal(image_size))
    image = _render(box, K, R, t, image_size, Style(clutter=False, jpeg_quality=None), int(seed), "front")
    scene = Scene(image=image, points={}, box=box, focal_px=focal, distance_mm=distance,
                  mm_per_px=None, view="oblique", camera_matrix=K, rotation=R, translation=t)
    left = box_vertices_px(scene)[1]
    right = np.column_stack([(w - 1) - left[:, 0], left[:, 1]])
    # The left half as rendered, the right half its mirror (the background stays continuous).
    img = np.ascontiguousarray(np.where(np.arange(w)[None, :, None] < w // 2, image, image[:, ::-1]))
    return _jpeg_round_trip(img, 90), [left, right]

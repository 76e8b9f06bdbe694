"""Photo-like scenes drawn from one seed: box, pose, camera, lens, clicks and known edge, for the
real-cameras benchmark and the several-views renders (`prismsynth.views`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from prismcore.errors import InputError

from .box_geometry import (
    _FILL_WIDTH,
    _auto_distance,
    _box_vertices,
    _camera_matrix,
    _oblique_pose,
    _principal,
    _project,
)
from .models import Box, CameraExif, Realism, Scene, Style
from .phone import distort_points
from .render import _scene

__all__ = ["PhotoLikeScene", "photo_like_clicks", "photo_like_pose", "photo_like_scene", "photo_like_setup"]


_PHONES = (("Apple", "iPhone 12"), ("samsung", "SM-G991B"), ("Google", "Pixel 7"), ("Xiaomi", "M2101K6G"),
           ("OnePlus", "LE2123"))
_POINT_ORDER = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
_CLICK_RADIUS_PX = 3.0
_FACE_ANGLES_DEG = (20.0, 60.0)  # front and side normals this far from the direction to the camera
_FRAME_MARGIN = 0.03  # every box corner at least this fraction of the width inside the picture


@dataclass(frozen=True, eq=False)
class PhotoLikeScene:
    """A rendered oblique photo made to look like a phone's, with what a user would give the engine.

    Attributes
    ----------
    scene : Scene
        The render: ``scene.image`` (H, W, 3) uint8 RGB decoded from ``scene.jpeg``; ``scene.points``
        the true corners where the lens put them, ``scene.camera_matrix`` and ``scene.distortion``
        the true camera.
    clicks : dict of str to (float, float)
        p1..p7 as a user clicks them: the true (distorted) corners moved by up to 3 px, uniformly
        over a disc, px.
    known_edge : str
        The edge whose true length the user gives: "width", "height" or "depth".
    has_exif : bool
        Whether the JPEG carries EXIF (make, model, FocalLengthIn35mmFilm, pixel dimensions).
    style : Style
    realism : Realism
    face_angles_deg : (float, float)
        Angle between the front (then the side) face's normal and the direction from its centre
        to the camera, degrees.
    """

    scene: Scene
    clicks: dict[str, tuple[float, float]]
    known_edge: str
    has_exif: bool
    style: Style
    realism: Realism
    face_angles_deg: tuple[float, float]

    @property
    def image(self) -> np.ndarray:
        return self.scene.image

    @property
    def jpeg(self) -> bytes:
        assert self.scene.jpeg is not None  # photo-like scenes are always JPEGs
        return self.scene.jpeg

    @property
    def box(self) -> Box:
        return self.scene.box

    @property
    def camera_matrix(self) -> np.ndarray:
        return self.scene.camera_matrix

    @property
    def distortion(self) -> np.ndarray:
        assert self.scene.distortion is not None
        return self.scene.distortion

    @property
    def known_length_mm(self) -> float:
        return float(getattr(self.box, f"{self.known_edge}_mm"))

    def click_list(self) -> list[tuple[float, float]]:
        """The clicks in the engine's order p1..p7."""
        return [self.clicks[n] for n in _POINT_ORDER]


def _rotation(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    rot = np.eye(3)
    rot[i, i], rot[i, j], rot[j, i], rot[j, j] = c, -s, s, c
    return rot


def _face_angles(box: Box, camera_centre: np.ndarray) -> tuple[float, float]:
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    out = []
    for centre, normal in (((W / 2, H / 2, 0.0), (0.0, 0.0, -1.0)), ((W, H / 2, D / 2), (1.0, 0.0, 0.0))):
        to_cam = camera_centre - np.asarray(centre)
        out.append(math.degrees(math.acos(float(np.dot(normal, to_cam)) / float(np.linalg.norm(to_cam)))))
    return out[0], out[1]


def photo_like_setup(rng: np.random.Generator, seed: int, image_size: tuple[int, int],
                     edge_radius_mm: float | None) -> tuple[Box, float, Realism, Style, np.ndarray]:
    """The box, focal length (px), lens, look and camera matrix a photo-like seed draws from
    `rng`, in this order (the order of the draws is what makes a seed's scene)."""
    w, _ = image_size
    box = Box(*(float(v) for v in rng.uniform([40.0, 30.0, 25.0], [300.0, 220.0, 180.0])))
    focal = float(rng.uniform(0.7, 1.2) * w)
    k1, k2 = float(rng.uniform(-0.15, 0.10)), float(rng.uniform(-0.03, 0.03))
    radius = float(min(rng.uniform(0.5, 2.5), 0.2 * min(box.width_mm, box.height_mm, box.depth_mm)))
    if edge_radius_mm is not None:
        radius = float(edge_radius_mm)
    realism = Realism(k1=k1, k2=k2, edge_radius_mm=radius,
                      vignetting=float(rng.uniform(0.1, 0.4)), shot_noise=float(rng.uniform(2.0, 6.0)),
                      exif=CameraExif(*_PHONES[int(rng.integers(len(_PHONES)))]) if seed % 2 == 0 else None)
    style = Style(texture=float(rng.uniform(3.0, 8.0)), lighting=float(rng.uniform(0.1, 0.5)),
                  noise_sigma=float(rng.uniform(1.0, 3.0)), blur_sigma=float(rng.uniform(0.5, 1.2)),
                  jpeg_quality=int(rng.integers(70, 96)), background_close=bool(rng.random() < 0.3))
    return box, focal, realism, style, _camera_matrix(focal, _principal(image_size))


def photo_like_clicks(rng: np.random.Generator, scene: Scene) -> dict[str, tuple[float, float]]:
    """A person's clicks on `scene`'s seven points: each up to `_CLICK_RADIUS_PX` off, uniform
    over the disc."""
    offset = _CLICK_RADIUS_PX * np.sqrt(rng.uniform(0.0, 1.0, 7))
    angle = rng.uniform(0.0, 2 * math.pi, 7)
    return {n: (scene.points[n][0] + float(r * math.cos(a)), scene.points[n][1] + float(r * math.sin(a)))
            for n, r, a in zip(_POINT_ORDER, offset, angle, strict=True)}


def photo_like_pose(rng: np.random.Generator, box: Box, K: np.ndarray, realism: Realism,
                    image_size: tuple[int, int],
                    accept: Callable[[np.ndarray], bool] = lambda camera: True,
                    ) -> tuple[np.ndarray, np.ndarray, tuple[float, float]] | None:
    """One try at a photo-like pose: R, t and the face angles, or None when this draw shows the
    faces at angles out of range, is not `accept`ed (given the camera's centre, mm), or puts the
    box outside the frame. Each try draws the same numbers from `rng`, accepted or not."""
    w, h = image_size
    focal = float(K[0, 0])
    lo, hi = _FACE_ANGLES_DEG
    yaw, pitch = float(rng.uniform(10.0, 80.0)), float(rng.uniform(5.0, 45.0))
    fill = float(rng.uniform(0.35, 0.6))
    roll = math.radians(rng.uniform(-8.0, 8.0))
    shift = rng.uniform(-0.12, 0.12, 2) * (w, h)
    d = _auto_distance(box, (w, h), focal, partial(_oblique_pose, box, yaw_deg=yaw, pitch_deg=pitch))
    R, t = _oblique_pose(box, d * _FILL_WIDTH / fill, yaw, pitch)
    angles = _face_angles(box, -R.T @ t)
    if not all(lo <= a <= hi for a in angles) or not accept(-R.T @ t):
        return None
    # Turn the camera about its own centre: the box lands off-centre and the horizon tilts.
    turn = (_rotation(2, roll) @ _rotation(1, -math.atan2(shift[0], focal))
            @ _rotation(0, math.atan2(shift[1], focal)))
    R, t = turn @ R, turn @ t
    verts = _box_vertices(box)
    if np.min((verts @ R.T + t)[:, 2]) <= 0:
        return None
    seen = distort_points(_project(K, R, t, verts), K, realism.distortion())
    margin = _FRAME_MARGIN * w
    if np.all((seen >= margin) & (seen <= np.array([w - 1, h - 1]) - margin)):
        return R, t, angles
    return None


def photo_like_scene(seed: int, *, image_size: tuple[int, int] = (1280, 960),
                     edge_radius_mm: float | None = None) -> PhotoLikeScene:
    """A random oblique photo of a random box, as a phone would take it and a user would click it.

    Drawn from `seed` alone: box sides 40-300 x 30-220 x 25-180 mm; a pose that shows the
    front, right and top faces with the front's and the side's normals 20-60 degrees from the
    view, the camera rolled up to 8 degrees and the box off-centre; a focal length of 0.7-1.2
    times the image width (phones' range); distortion k1 uniform in [-0.15, 0.10] and k2 in
    [-0.03, 0.03]; rounded edges 0.5-2.5 mm; vignetting 0.1-0.4; read and shot noise; blur;
    JPEG quality 70-95, with EXIF for even seeds (half of any run of seeds); the clicks 0-3 px
    off (uniform over a disc); one known edge.

    Parameters
    ----------
    seed : int
        Everything follows from it (same seed, same bytes).
    image_size : (int, int)
        (width, height) px.
    edge_radius_mm : float or None
        Overrides the drawn edge radius (everything else stays as the seed draws it), e.g. 0 to
        see what the rounding alone costs.

    Returns
    -------
    PhotoLikeScene
    """
    w, h = int(image_size[0]), int(image_size[1])
    if min(w, h) < 64:
        raise InputError(f"image_size must be at least 64x64 px, got {image_size!r}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 15]))
    box, focal, realism, style, K = photo_like_setup(rng, seed, (w, h), edge_radius_mm)
    for _ in range(1000):
        if (pose := photo_like_pose(rng, box, K, realism, (w, h))) is not None:
            R, t, angles = pose
            break
    else:  # pragma: no cover - the ranges above leave plenty of poses
        raise RuntimeError(f"no photo-like pose found for seed {seed}")
    front_centre = R @ np.array([box.width_mm / 2, box.height_mm / 2, 0.0]) + t
    scene = _scene(box, "oblique", (w, h), focal, float(front_centre[2]), R, t, style,
                   int(rng.integers(1 << 31)), _POINT_ORDER, "front", None, realism=realism)
    clicks = photo_like_clicks(rng, scene)
    known = str(rng.choice(["width", "height", "depth"]))
    return PhotoLikeScene(scene, clicks, known, realism.exif is not None, style, realism, angles)

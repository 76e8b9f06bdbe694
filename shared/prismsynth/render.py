"""Synthetic photos of a rectangular box (a "prism") of known size: ground truth for the engine.

A box ``[0, W] x [0, H] x [0, D]`` (mm) is photographed by a pinhole camera. Its visible
faces carry a textured, shaded, labelled surface; the background is cluttered; the photo
then gets optical blur, sensor noise and a JPEG round trip. The exact image positions of
the reference points P1..P7 come with the image, as does the camera.

Conventions
-----------
* Image pixel coordinates ``(x, y) = (column, row)``, origin top-left, integer coordinates
  at pixel *centres* (OpenCV's: pixel ``(0, 0)`` covers ``[-0.5, 0.5]^2``). Images are RGB
  ``uint8`` arrays of shape ``(H, W, 3)``.
* Box world frame: origin at the front face's upper-left corner, X right along the front's
  top edge, Y down the front face, Z into the object. The side face is the right face
  ``x = W``.
* Reference points: P1 ``(0,0,0)``, P2 ``(W,0,0)``, P3 ``(W,H,0)``, P6 ``(0,H,0)`` on the
  front; P4 ``(W,0,0)``, P5 ``(W,0,D)``, P7 ``(W,H,D)`` on the side. In a square side view
  "p3" is the side face's lower-left corner ``(W,H,0)``.
* Camera: ``K = [[f,0,cx],[0,f,cy],[0,0,1]]`` with ``cx = (width-1)/2``, ``cy = (height-1)/2``;
  camera frame x right, y down, z forward; a world point X maps to ``R @ X + t``.

How a scene is made
-------------------
Each visible face (back faces are culled) gets a texture in its own plane (grain, fibres,
mottling, a printed label, Lambertian shade and a smooth lighting gradient), warped into
a 3x supersampled image by the face's plane-to-image homography and area-averaged down.
Its coverage of each output pixel is computed analytically (the exact area of the pixel
square on the inner side of each projected edge), so edges are anti-aliased and sub-pixel
exact: the 50% crossing of a face's edge is where the projection puts it. The faces'
coverages of a shared edge add up to one, so no background leaks through the seams.

Photos that look like a phone's (opt in: ``realism=Realism(...)``)
-------------------------------------------------------------------
The ideal pinhole photo (its box's edges rounded when asked) is rendered on a canvas large
enough for the lens, then warped so that every point lands where OpenCV's distortion model
puts it (``Scene.points`` are those distorted positions, ``Scene.pinhole_points`` the ideal
ones), darkened toward the corners, blurred, given read and shot noise and encoded as a JPEG by
Pillow, EXIF included (``Scene.jpeg``). `photo_like_scene` draws whole such scenes (box, pose,
camera, lens, clicks, known edge) from one seed for the real-cameras benchmark. Without
`realism` every render is exactly what it was before the option existed.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import cast

import cv2
import numpy as np
from PIL import Image

from prismcore.errors import InputError

__all__ = [
    "Box",
    "CameraExif",
    "PhotoLikeScene",
    "Realism",
    "Scene",
    "Style",
    "decode_jpeg",
    "distort_points",
    "encode_jpeg",
    "focal_35mm_equivalent",
    "photo_like_scene",
    "render_front_view",
    "render_oblique_view",
    "render_side_view",
    "save_image",
    "vignetting_gain",
]

_SUPERSAMPLE = 3  # face textures are warped at this many samples per output pixel per axis
_TEXELS_PER_PX = 1.5  # texture density at the face's nearest point, texels per output pixel
_MAX_TEXELS = 3000  # per texture side
_FILL_WIDTH = 0.5  # automatic distance: the box spans this fraction of the image width...
_MAX_FILL_HEIGHT = 0.75  # ...unless that makes it taller than this fraction of the height
_SAVE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP", ".tif": "TIFF",
                 ".tiff": "TIFF", ".webp": "WEBP"}


@dataclass(frozen=True)
class Box:
    """True size of the box, mm: width along X, height along Y, depth along Z."""

    width_mm: float
    height_mm: float
    depth_mm: float

    def __post_init__(self) -> None:
        for name in ("width_mm", "height_mm", "depth_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Box.{name} must be a positive finite number, got {value!r}")

    def __str__(self) -> str:
        return f"{self.width_mm:g}x{self.height_mm:g}x{self.depth_mm:g}"


@dataclass(frozen=True)
class Style:
    """How realistic (and how hard) a scene is. All randomness comes from the render's seed.

    Attributes
    ----------
    label : bool
        A printed label (paper rectangle with a barcode, text and a logo) on the front face
        and, by chance, on the other visible faces; inset at least 12% of the face's size.
    texture : float
        Amplitude (standard deviation, 0-255 units) of the surface grain, fibres and mottling.
    lighting : float
        Strength of the smooth lighting gradient across each face: its brightness varies by
        about this fraction. Also sets the soft shadow the box casts on the background
        (none when 0). The per-face Lambertian shade is always applied.
    noise_sigma : float
        Gaussian sensor noise, standard deviation in 0-255 units, per channel.
    blur_sigma : float
        Gaussian optical blur, standard deviation in output pixels (0 = none).
    jpeg_quality : int or None
        Quality of the final JPEG round trip, 1-100; None for no JPEG.
    clutter : bool
        Cluttered background (gradients, a table edge, shapes, lines, text); else uniform.
    background_close : bool
        Background colour within about 20 RGB of the photographed face's mean colour (the
        front face in front and oblique views); clutter stays in the same colour family.
    box_color : tuple of 3 int or None
        Base RGB colour of the box before shading; random if None.
    texel_mm : float or None
        Fixed texture density, mm per texel, so that frames of one scene from different poses
        (a moving camera's clip) show the same texture; None: set by each render's distance.
    """

    label: bool = True
    texture: float = 6.0
    lighting: float = 0.25
    noise_sigma: float = 2.0
    blur_sigma: float = 0.6
    jpeg_quality: int | None = 90
    clutter: bool = True
    background_close: bool = False
    box_color: tuple[int, int, int] | None = None
    texel_mm: float | None = None

    def __post_init__(self) -> None:
        for name in ("texture", "lighting", "noise_sigma", "blur_sigma"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"Style.{name} must be >= 0, got {value!r}")
        if self.jpeg_quality is not None and not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"Style.jpeg_quality must be 1-100 or None, got {self.jpeg_quality!r}")
        if self.box_color is not None and (len(self.box_color) != 3
                                           or not all(0 <= c <= 255 for c in self.box_color)):
            raise ValueError(f"Style.box_color must be 3 values 0-255, got {self.box_color!r}")


DEFAULT_STYLE = Style()


@dataclass(frozen=True)
class CameraExif:
    """What a phone writes into its photos' EXIF besides the focal length."""

    make: str = "Synthphone"
    model: str = "SP-1"


@dataclass(frozen=True)
class Realism:
    """Opt-in imperfections of real photos, on top of a `Style` (all off by default).

    The ideal pinhole photo is rendered first (with rounded edges when asked), then warped by
    the lens distortion, darkened toward the corners, blurred (``Style.blur_sigma``), given
    sensor noise (``Style.noise_sigma`` plus shot noise) and encoded as a JPEG at
    ``Style.jpeg_quality`` by Pillow (with EXIF when `exif` is set); the scene's image is that
    JPEG decoded and ``Scene.jpeg`` its bytes.

    Attributes
    ----------
    k1, k2 : float
        OpenCV radial distortion coefficients (normalised coordinates): a point the pinhole
        puts at normalised (x, y) lands at (x, y) * (1 + k1 r^2 + k2 r^4), r^2 = x^2 + y^2.
        Negative k1 is barrel distortion (phones: about -0.15 to 0.10).
    edge_radius_mm : float
        Radius of the box's rounded edges, mm; the box keeps its outer size, so the silhouette
        lies inside the sharp box's outline and the faces' shading turns along every edge.
    vignetting : float
        Fraction by which the image's corner pixels are darkened, 0 <= v < 1; the gain falls
        as ``1 - v * rho^2``, rho the distance from the image centre over the corners' distance.
    shot_noise : float
        Signal-dependent sensor noise: standard deviation at full white (255), 0-255 units;
        it scales with the square root of the pixel value.
    exif : CameraExif or None
        Write EXIF into the JPEG: make, model, pixel dimensions and FocalLengthIn35mmFilm
        (from the scene's focal length). Needs ``Style.jpeg_quality``.
    """

    k1: float = 0.0
    k2: float = 0.0
    edge_radius_mm: float = 0.0
    vignetting: float = 0.0
    shot_noise: float = 0.0
    exif: CameraExif | None = None

    def __post_init__(self) -> None:
        for name in ("k1", "k2"):
            if not math.isfinite(getattr(self, name)):
                raise InputError(f"Realism.{name} must be finite, got {getattr(self, name)!r}")
        for name in ("edge_radius_mm", "shot_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"Realism.{name} must be >= 0, got {value!r}")
        if not (math.isfinite(self.vignetting) and 0 <= self.vignetting < 1):
            raise InputError(f"Realism.vignetting must be in [0, 1), got {self.vignetting!r}")

    def distortion(self) -> np.ndarray:
        """(5,) float64 OpenCV distortion coefficients (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, 0.0, 0.0, 0.0])


class _Points(dict[str, tuple[float, float]]):
    """Point name -> (x, y) px. Keys are the engine's ("p1".."p7"); lookups ignore case."""

    def __getitem__(self, key: str) -> tuple[float, float]:
        return super().__getitem__(key.lower())

    def __contains__(self, key: object) -> bool:
        return super().__contains__(key.lower() if isinstance(key, str) else key)

    def get(self, key: str,  # type: ignore[override]
            default: tuple[float, float] | None = None) -> tuple[float, float] | None:
        return super().get(key.lower(), default)


@dataclass(frozen=True, eq=False)
class Scene:
    """A rendered photo and its ground truth.

    Attributes
    ----------
    image : np.ndarray
        (H, W, 3) uint8 RGB.
    points : dict of str to (float, float)
        Exact projected reference points, px (x = column, y = row, integers at pixel
        centres). Keys are lowercase as in the engine ("p1".."p7"); lookups such as
        ``points["P1"]`` also work. Front view: p1, p2, p3, p6. Side view: p4, p5, p7 and
        p3 (the side face's lower-left corner, (W, H, 0)). Oblique view: p1..p7.
    box : Box
        True size.
    focal_px : float
        Focal length, px.
    distance_mm : float
        Depth along the optical axis (camera z) of the centre of the photographed face: the
        front face for front and oblique views, the side face for the side view.
    mm_per_px : float or None
        Square views: ``distance_mm / focal_px``, the exact scale in the face's plane.
        None for the oblique view.
    view : str
        "front", "side" or "oblique".
    camera_matrix : np.ndarray
        (3, 3) float64 K.
    rotation : np.ndarray
        (3, 3) float64 world-to-camera rotation R.
    translation : np.ndarray
        (3,) float64 world-to-camera translation t, mm: ``X_cam = R @ X_world + t``.
    distortion : np.ndarray or None
        (5,) float64 OpenCV distortion (k1, k2, p1, p2, k3) the photo was taken with (a
        `Realism` render); None for a pinhole render. With distortion, `points` are where the
        lens puts the corners (OpenCV's forward model of `pinhole_points`).
    pinhole_points : dict of str to (float, float) or None
        A `Realism` render: where an ideal pinhole camera (K, R, t) projects the points, px.
    jpeg : bytes or None
        A `Realism` render with a JPEG quality: the JPEG file (with EXIF when asked for);
        `image` is its decoding.
    """

    image: np.ndarray
    points: dict[str, tuple[float, float]]
    box: Box
    focal_px: float
    distance_mm: float
    mm_per_px: float | None
    view: str
    camera_matrix: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    distortion: np.ndarray | None = None
    pinhole_points: dict[str, tuple[float, float]] | None = None
    jpeg: bytes | None = None


# --------------------------------------------------------------------------- geometry


def _camera_matrix(focal_px: float, principal: tuple[float, float]) -> np.ndarray:
    return np.array([[focal_px, 0.0, principal[0]], [0.0, focal_px, principal[1]], [0.0, 0.0, 1.0]])


def _principal(image_size: tuple[int, int]) -> tuple[float, float]:
    return (image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0


def _project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pinhole projection of (N, 3) world points to (N, 2) px."""
    cam = X @ R.T + t
    uvw = cam @ K.T
    px: np.ndarray = uvw[:, :2] / uvw[:, 2:3]
    return px


def _corners(box: Box) -> dict[str, np.ndarray]:
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    return {"p1": np.array([0.0, 0.0, 0.0]), "p2": np.array([W, 0.0, 0.0]),
            "p3": np.array([W, H, 0.0]), "p4": np.array([W, 0.0, 0.0]),
            "p5": np.array([W, 0.0, D]), "p6": np.array([0.0, H, 0.0]),
            "p7": np.array([W, H, D])}


def _second_face_corners(box: Box, side_face: str) -> dict[str, np.ndarray]:
    """p4, p5, p7 of the second face by role (see prismcore.geometry.faces): right, left or top."""
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    if side_face == "left":
        return {"p4": np.zeros(3), "p5": np.array([0.0, 0.0, D]), "p7": np.array([0.0, H, D])}
    if side_face == "top":
        return {"p4": np.zeros(3), "p5": np.array([0.0, 0.0, D]), "p7": np.array([W, 0.0, D])}
    return {n: c for n, c in _corners(box).items() if n in ("p4", "p5", "p7")}


def _box_vertices(box: Box) -> np.ndarray:
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    return np.array([[x, y, z] for x in (0, W) for y in (0, H) for z in (0, D)], dtype=np.float64)


@dataclass(frozen=True)
class _Face:
    name: str
    origin: np.ndarray  # (3,) world mm, the texture's (u, v) = (0, 0) corner
    e_u: np.ndarray  # (3,) unit vector of texture u (columns)
    e_v: np.ndarray  # (3,) unit vector of texture v (rows)
    size_u: float  # mm
    size_v: float  # mm
    normal: np.ndarray  # (3,) outward unit normal

    def corners(self) -> np.ndarray:
        """(4, 3) world corners in texture order (0,0), (U,0), (U,V), (0,V)."""
        u, v = self.e_u * self.size_u, self.e_v * self.size_v
        return np.array([self.origin, self.origin + u, self.origin + u + v, self.origin + v])


def _faces(box: Box) -> list[_Face]:
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    X, Y, Z = np.eye(3)
    o = np.zeros(3)
    return [
        _Face("front", o, X, Y, W, H, -Z),
        _Face("right", np.array([W, 0.0, 0.0]), Z, Y, D, H, X),
        _Face("top", np.array([0.0, 0.0, D]), X, -Z, W, D, -Y),
        _Face("left", np.array([0.0, 0.0, D]), -Z, Y, D, H, -X),
        _Face("back", np.array([W, 0.0, D]), -X, Y, W, H, Z),
        _Face("bottom", np.array([0.0, H, 0.0]), X, Z, W, D, Y),
    ]


def _square_pose(box: Box, view: str, focal_px: float, distance_mm: float,
                 offset_px: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """R, t of a camera squarely facing the front (or side) face, its centre at the offset."""
    W, H, D = box.width_mm, box.height_mm, box.depth_mm
    if view == "front":
        R = np.eye(3)
        centre = np.array([W / 2, H / 2, 0.0])
    else:  # camera at +X looking at -X; image right = +Z, image down = +Y
        R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
        centre = np.array([W, H / 2, D / 2])
    target = np.array([offset_px[0] * distance_mm / focal_px, offset_px[1] * distance_mm / focal_px,
                       distance_mm])
    return R, target - R @ centre


def _oblique_pose(box: Box, distance_mm: float, yaw_deg: float,
                  pitch_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """R, t of a camera aimed at the front face's centre from the front-right and above."""
    yaw, pitch = math.radians(yaw_deg), math.radians(pitch_deg)
    target = np.array([box.width_mm / 2, box.height_mm / 2, 0.0])
    toward_camera = np.array([math.sin(yaw) * math.cos(pitch), -math.sin(pitch),
                              -math.cos(yaw) * math.cos(pitch)])
    centre = target + distance_mm * toward_camera
    z = -toward_camera
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ centre


def _auto_distance(box: Box, image_size: tuple[int, int], focal_px: float,
                   pose: Callable[[float], tuple[np.ndarray, np.ndarray]]) -> float:
    """Distance at which the box's projection spans _FILL_WIDTH of the image width (or
    _MAX_FILL_HEIGHT of its height, whichever is reached first)."""
    K = _camera_matrix(focal_px, _principal(image_size))
    verts = _box_vertices(box)
    d = focal_px * max(box.width_mm, box.height_mm, box.depth_mm) / (_FILL_WIDTH * image_size[0])
    for _ in range(30):
        R, t = pose(d)
        if np.min((verts @ R.T + t)[:, 2]) <= 1e-6 * d:
            d *= 2.0
            continue
        pts = _project(K, R, t, verts)
        ratio = max(np.ptp(pts[:, 0]) / (_FILL_WIDTH * image_size[0]),
                    np.ptp(pts[:, 1]) / (_MAX_FILL_HEIGHT * image_size[1]))
        if abs(ratio - 1.0) < 1e-9:
            break
        d *= ratio
    return float(d)


# --------------------------------------------------------------------------- coverage


def _halfplane_coverage(s: np.ndarray, nx: float, ny: float) -> np.ndarray:
    """Exact fraction of a unit pixel square inside the half-plane ``n . q + c >= 0``.

    ``s`` is the signed distance of the pixel centres from the line (positive inside) and
    (nx, ny) the unit normal. The projection of a uniform point of the square on n is the
    sum of two uniforms of widths |nx| and |ny|, so the coverage is that sum's CDF at s.
    """
    a, b = max(abs(nx), abs(ny)), min(abs(nx), abs(ny))
    if b < 1e-6:
        return np.clip(s / a + 0.5, 0.0, 1.0)
    h1, h0 = (a + b) / 2, (a - b) / 2
    t = np.clip(s, -h1, h1)

    def q(x: np.ndarray) -> np.ndarray:
        half_square: np.ndarray = np.square(np.maximum(x, 0.0)) / 2
        return half_square

    coverage: np.ndarray = np.clip((q(t + h1) - q(t + h0) - q(t - h0) + q(t - h1)) / (a * b), 0.0, 1.0)
    return coverage


def _polygon_coverage(poly: np.ndarray, x0: int, y0: int, w: int, h: int) -> np.ndarray:
    """Coverage (h, w) float64 of output pixels [x0, x0+w) x [y0, y0+h) by a convex polygon.

    The product of the exact half-plane coverages: exact away from the vertices (and at
    the vertices of axis-aligned edges).
    """
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    if area < 0:  # orient counter-clockwise in (x, y-down) so that "inside" is on the left
        poly = poly[::-1]
    xs = np.arange(x0, x0 + w, dtype=np.float64)[None, :]
    ys = np.arange(y0, y0 + h, dtype=np.float64)[:, None]
    cov = np.ones((h, w))
    for p, q in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        d = q - p
        length = math.hypot(d[0], d[1])
        if length < 1e-12:
            continue
        nx, ny = -d[1] / length, d[0] / length  # left normal of p -> q
        cov *= _halfplane_coverage(nx * (xs - p[0]) + ny * (ys - p[1]), nx, ny)
    return cov


# --------------------------------------------------------------------------- colours


_BOX_PALETTE = [
    (182, 140, 96), (196, 160, 112), (165, 120, 80),  # kraft cardboard
    (228, 226, 218), (210, 212, 214), (150, 152, 156), (88, 90, 96),  # white, greys
    (60, 95, 160), (170, 45, 45), (55, 130, 80), (215, 180, 60), (225, 120, 40),  # plastics
    (120, 80, 140), (70, 150, 160),
]


def _box_color(rng: np.random.Generator, style: Style) -> np.ndarray:
    if style.box_color is not None:
        return np.asarray(style.box_color, dtype=np.float64)
    base = np.asarray(_BOX_PALETTE[rng.integers(len(_BOX_PALETTE))], dtype=np.float64)
    return np.clip(base + rng.uniform(-15, 15, 3), 20, 240)


def _light(rng: np.random.Generator) -> np.ndarray:
    """Unit direction toward the light (world), from above and in front, chosen so that
    adjacent faces get clearly different Lambertian shades."""
    for _ in range(200):
        lx, ly, lz = rng.uniform(-0.9, 0.9), -rng.uniform(0.25, 1.0), -rng.uniform(0.45, 1.0)
        light = np.array([lx, ly, lz]) / math.sqrt(lx * lx + ly * ly + lz * lz)
        front, right, top = (_lambert(n, light) for n in ([0, 0, -1], [1, 0, 0], [0, -1, 0]))
        if abs(front - right) >= 0.12 and abs(front - top) >= 0.08 and abs(right - top) >= 0.08:
            return light
    return np.array([0.45, -0.45, -0.77])


def _lambert(normal: np.ndarray | list[int], light: np.ndarray) -> float:
    return 0.42 + 0.58 * max(0.0, float(np.dot(normal, light)))


def _random_color(rng: np.random.Generator) -> np.ndarray:
    c = rng.uniform(20, 235, 3)
    grey = c.mean()
    muted: np.ndarray = grey + (c - grey) * rng.uniform(0.15, 0.85)  # mostly muted, like real rooms
    return muted


def _contrasting(rng: np.random.Generator, face: np.ndarray, min_dist: float = 70.0) -> np.ndarray:
    for _ in range(200):
        c = _random_color(rng)
        if np.linalg.norm(c - face) >= min_dist:
            return c
    return np.where(face > 127, 40.0, 215.0)


def _near(rng: np.random.Generator, color: np.ndarray, spread: float) -> np.ndarray:
    return np.clip(color + rng.uniform(-spread, spread, 3), 0, 255)


# --------------------------------------------------------------------------- background


def _low_freq(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    """Smooth random field (h, w) float32, zero mean, unit std."""
    gh, gw = max(2, round(cells * h / max(h, w))), max(2, round(cells * w / max(h, w)))
    small = rng.standard_normal((gh, gw)).astype(np.float32)
    field = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    normalised: np.ndarray = (field - field.mean()) / (field.std() + 1e-6)
    return normalised


def _background(rng: np.random.Generator, size: tuple[int, int], style: Style,
                face: np.ndarray) -> np.ndarray:
    """Background (H, W, 3) float32 RGB, 0-255. `face` is the photographed face's colour."""
    w, h = size
    if style.background_close:
        base = face + rng.uniform(-1, 1, 3) * rng.uniform(6, 11)  # ~10-19 RGB away
        family = 25.0  # shapes; the surfaces stay within about 20
    else:
        base = _contrasting(rng, face)
        family = None
    img: np.ndarray = np.empty((h, w, 3), np.float32)  # float32, uint8 to draw on, float32
    img[:] = base
    if not style.clutter:
        return img

    def color(strong: bool = False) -> tuple[float, ...]:
        if family is not None:
            c = _near(rng, base, family)
        elif strong or rng.random() < 0.6:
            c = _random_color(rng)
        else:
            c = _near(rng, base, 45.0)
        return tuple(float(v) for v in c)

    # Smooth gradient and blotches (uneven light on a wall or a table).
    ang = rng.uniform(0, 2 * math.pi)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    ramp = ((xx - w / 2) * math.cos(ang) + (yy - h / 2) * math.sin(ang)) / max(w, h)
    amp = 8.0 if family is not None else 30.0
    img += (ramp * amp * 2)[..., None]
    img += (_low_freq(rng, h, w, 6) * amp * 0.4)[..., None]
    # A table edge: a straight line across the picture with another surface beyond it.
    if rng.random() < 0.7:
        y_left, y_right = rng.uniform(0.05, 0.95, 2) * h
        beyond = np.asarray(color() if family is None else _near(rng, base, 14.0), np.float32)
        mask = np.zeros((h, w), np.uint8)
        upper = rng.random() < 0.5
        pts = [(0, y_left), (w - 1, y_right), (w - 1, 0 if upper else h - 1), (0, 0 if upper else h - 1)]
        cv2.fillPoly(mask, [np.round(np.array(pts) * 16).astype(np.int32)], 255, cv2.LINE_AA, shift=4)
        m = (mask.astype(np.float32) / 255)[..., None]
        img = img * (1 - m) + (beyond + (_low_freq(rng, h, w, 4) * amp * 0.3)[..., None]) * m
    # OpenCV draws text (and anti-aliased shapes) on 8-bit images only.
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    # Shapes: boxes, discs, triangles, some outlined, some translucent.
    scale = max(w, h)
    for _ in range(int(rng.integers(12, 26))):
        layer = img.copy()
        c = color()
        kind = rng.integers(4)
        cx, cy = rng.uniform(-0.05, 1.05) * w, rng.uniform(-0.05, 1.05) * h
        r = rng.uniform(0.02, 0.15) * scale
        thick = -1 if rng.random() < 0.7 else int(rng.integers(2, 6))
        if kind == 0 or kind == 1:
            ang = rng.uniform(0, 180) if kind == 1 else rng.choice([0.0, 90.0]) + rng.normal(0, 3)
            rect = ((cx, cy), (r * rng.uniform(0.6, 2.0), r * rng.uniform(0.3, 1.5)), ang)
            poly = cv2.boxPoints(rect)
            _poly(layer, poly, c, thick)
        elif kind == 2:
            axes = (round(r * 16), round(r * rng.uniform(0.4, 1.0) * 16))
            cv2.ellipse(layer, (round(cx * 16), round(cy * 16)), axes, rng.uniform(0, 180), 0, 360, c,
                        thick, cv2.LINE_AA, 4)
        else:
            poly = np.array([cx, cy]) + rng.uniform(-r, r, (3, 2))
            _poly(layer, poly, c, thick)
        alpha = 1.0 if rng.random() < 0.75 else rng.uniform(0.3, 0.7)
        img = layer if alpha == 1.0 else cv2.addWeighted(layer, alpha, img, 1 - alpha, 0)
    # Straight lines: cables, shelf and tile edges, pencils.
    for _ in range(int(rng.integers(6, 16))):
        p = rng.uniform(-0.1, 1.1, 2) * (w, h)
        ang = rng.uniform(0, math.pi)
        length = rng.uniform(0.1, 1.2) * scale
        q = p + length * np.array([math.cos(ang), math.sin(ang)])
        cv2.line(img, _fix(p), _fix(q), color(strong=True), int(rng.integers(1, 5)), cv2.LINE_AA, 4)
    # Text-like marks (a newspaper, a printed sheet).
    for _ in range(int(rng.integers(1, 4))):
        x, y = rng.uniform(0, 0.9) * w, rng.uniform(0.05, 0.95) * h
        c = color(strong=True)
        font_scale = rng.uniform(0.4, 1.0)
        for line in range(int(rng.integers(2, 6))):
            cv2.putText(img, _words(rng, 14), (round(x), round(y + line * 30 * font_scale)),
                        cv2.FONT_HERSHEY_SIMPLEX, font_scale, c, 1, cv2.LINE_AA)
    # Fine grain of the surfaces.
    img = img.astype(np.float32)
    grain = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 0.8)
    img += (grain * (1.5 + 0.5 * style.texture))[..., None]
    return img


def _fix(p: np.ndarray) -> tuple[int, int]:
    """A point in OpenCV's 4-bit fixed point (shift=4)."""
    return round(float(p[0]) * 16), round(float(p[1]) * 16)


def _poly(img: np.ndarray, poly: np.ndarray, color: tuple[float, ...], thick: int) -> None:
    pts = [np.round(np.asarray(poly) * 16).astype(np.int32)]
    if thick < 0:
        cv2.fillPoly(img, pts, color, cv2.LINE_AA, shift=4)
    else:
        cv2.polylines(img, pts, True, color, thick, cv2.LINE_AA, shift=4)


def _fit_text(rng: np.random.Generator, room: int, scale: float, thick: int) -> str:
    """Random words that fit in `room` px, stopping at a random fill of the line."""
    goal = room * rng.uniform(0.4, 1.0)
    text = ""
    for _ in range(20):
        longer = (text + " " if text else "") + _words(rng, 1)
        width = cv2.getTextSize(longer, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0]
        if width > goal:
            break
        text = longer
    return text


def _words(rng: np.random.Generator, n: int) -> str:
    letters = "ABCDEFGHIJKLMNOPRSTUVWXYZ0123456789"
    out: list[str] = []
    while sum(len(x) + 1 for x in out) < n:
        out.append("".join(letters[i] for i in rng.integers(len(letters), size=int(rng.integers(2, 8)))))
    return " ".join(out)


# --------------------------------------------------------------------------- face textures


def _grain(rng: np.random.Generator, nv: int, nu: int, amplitude: float) -> np.ndarray:
    """Grain + fibres + mottling (nv, nu) float32 with std about `amplitude`."""
    if amplitude <= 0:
        return np.zeros((nv, nu), np.float32)
    fine = cv2.GaussianBlur(rng.standard_normal((nv, nu)).astype(np.float32), (0, 0), 0.7)
    fibres: np.ndarray = rng.standard_normal((nv, nu)).astype(np.float32)
    horizontal = rng.random() < 0.5
    fibres = cv2.GaussianBlur(fibres, (0, 0), sigmaX=6.0 if horizontal else 0.6,
                              sigmaY=0.6 if horizontal else 6.0)
    mottle = _low_freq(rng, nv, nu, 8)
    out = (0.75 * fine / (fine.std() + 1e-6) + 0.45 * fibres / (fibres.std() + 1e-6)
           + 0.45 * mottle)
    grain: np.ndarray = out * amplitude
    return grain


def _lighting_field(rng: np.random.Generator, nv: int, nu: int, strength: float) -> np.ndarray:
    """Multiplicative lighting (nv, nu) float32: 1 +- strength/2, smooth."""
    if strength <= 0:
        return np.ones((nv, nu), np.float32)
    v, u = np.mgrid[0:nv, 0:nu].astype(np.float32)
    u, v = u / max(nu - 1, 1) - 0.5, v / max(nv - 1, 1) - 0.5
    ang = rng.uniform(0, 2 * math.pi)
    ramp = u * math.cos(ang) + v * math.sin(ang)
    hx, hy = rng.uniform(-0.5, 0.5, 2)
    spot = np.exp(-((u - hx) ** 2 + (v - hy) ** 2) / (2 * rng.uniform(0.2, 0.5) ** 2))
    g = 0.7 * ramp + 0.5 * spot
    g = (g - g.min()) / (np.ptp(g) + 1e-6) - 0.5  # exactly spans [-0.5, 0.5]
    field: np.ndarray = 1.0 + strength * g
    return field


def _draw_label(rng: np.random.Generator, albedo: np.ndarray, texture: float) -> None:
    """Paint a printed label (paper, barcode, text, logo) on (nv, nu, 3) albedo, in place,
    inset at least 12% of the face's size from its edges."""
    nv, nu = albedo.shape[:2]
    lw = int(nu * rng.uniform(0.35, 0.7))
    lh = int(nv * rng.uniform(0.3, 0.6))
    lw, lh = min(lw, int(0.74 * nu)), min(lh, int(0.74 * nv))
    if lw < 12 or lh < 8:
        return
    x0 = int(rng.uniform(0.13 * nu, 0.87 * nu - lw))
    y0 = int(rng.uniform(0.13 * nv, 0.87 * nv - lh))
    paper = np.clip(rng.choice([245.0, 238.0, 230.0]) + rng.uniform(-8, 8, 3), 200, 252)
    if rng.random() < 0.25:  # a coloured label
        paper = np.clip(_random_color(rng) * 0.4 + 150, 0, 250)
    ink = np.clip(rng.uniform(10, 50, 3), 0, 255)
    lab = np.empty((lh, lw, 3), np.uint8)
    lab[:] = np.round(paper).astype(np.uint8)
    ink_t = tuple(int(c) for c in ink)
    # Border.
    if rng.random() < 0.6:
        m = max(2, lw // 40)
        cv2.rectangle(lab, (m, m), (lw - 1 - m, lh - 1 - m), ink_t, max(1, lw // 150), cv2.LINE_AA)
    # Barcode in a lower part of the label.
    bw, bh = int(lw * rng.uniform(0.35, 0.6)), int(lh * rng.uniform(0.2, 0.35))
    bx, by = int(lw * rng.uniform(0.06, 0.94) - bw * rng.uniform(0, 1)), int(lh * 0.9) - bh
    bx = min(max(bx, lw // 15), lw - bw - lw // 15)
    unit = max(1.0, bw / 95.0)
    x = float(bx)
    while x < bx + bw:
        width = unit * rng.integers(1, 4)
        if rng.random() < 0.5:
            cv2.rectangle(lab, (round(x), by), (max(round(x), round(x + width) - 1), by + bh), ink_t, -1)
        x += width
    # A logo in the upper right corner.
    r = max(3, min(lw, lh) // 10)
    logo_left = lw
    if rng.random() < 0.7:
        c = tuple(int(v) for v in np.clip(_random_color(rng) * 1.2, 0, 255))
        cx, cy = lw - lw // 12 - r, lh // 12 + r
        logo_left = cx - r
        if rng.random() < 0.5:
            cv2.circle(lab, (cx, cy), r, c, -1, cv2.LINE_AA)
        else:
            cv2.rectangle(lab, (cx - r, cy - r), (cx + r, cy + r), c, -1)
    # Lines of text above the barcode, each fitted to the room it has.
    font_h = max(6, lh // int(rng.integers(9, 15)))
    scale = font_h / 22.0
    thick = max(1, round(scale * rng.uniform(1.0, 2.0)))
    left = lw // 12
    y = lh // 12 + font_h
    while y < by - font_h // 2:
        right = logo_left - lw // 30 if y - font_h < lh // 12 + 2 * r + 4 else lw - lw // 12
        text = _fit_text(rng, right - left, scale, thick)
        if text:
            cv2.putText(lab, text, (left, y), cv2.FONT_HERSHEY_SIMPLEX, scale, ink_t, thick, cv2.LINE_AA)
        y += int(font_h * rng.uniform(1.4, 1.9))
    region = lab.astype(np.float32)
    if texture > 0:
        region += (cv2.GaussianBlur(rng.standard_normal((lh, lw)).astype(np.float32), (0, 0), 0.7)
                   * texture * 0.5)[..., None]
    albedo[y0:y0 + lh, x0:x0 + lw] = region


# --------------------------------------------------------------------------- rounded edges


_ARC_SAMPLES = 2001  # samples of a rounded edge's quarter circle


@dataclass(frozen=True)
class _RoundedFace:
    """A face of a box whose edges are quarter cylinders of radius r (the box keeps its outer size).

    Per edge of the face, in the face's texture order (v = 0, u = U, v = V, u = 0): the in-face
    distance ``s`` (mm) from the sharp edge at which the silhouette lies (0 for a fold edge,
    whose neighbour face is visible too), and the table ``s -> shade ratio`` of the strip
    ``s < r``, where the camera sees the rounded surface instead of the face's plane.
    """

    face: _Face
    silhouette_mm: tuple[float, float, float, float]
    strips: tuple[tuple[np.ndarray, np.ndarray], ...]  # per edge: increasing s (mm), shade ratio
    radius_mm: float

    def silhouette_corners(self) -> np.ndarray:
        """(4, 3) world corners of the face's visible outline (edges moved in to the silhouette)."""
        f = self.face
        top, right, bottom, left = self.silhouette_mm
        u0, u1, v0, v1 = left, f.size_u - right, top, f.size_v - bottom
        corners = ((u0, v0), (u1, v0), (u1, v1), (u0, v1))
        return np.array([f.origin + u * f.e_u + v * f.e_v for u, v in corners])

    def shade_ratio(self, K: np.ndarray, R: np.ndarray, t: np.ndarray, x0: int, y0: int, w: int,
                    h: int) -> np.ndarray:
        """(h, w) float32 factor on the flat face's colour for pixels [x0, x0+w) x [y0, y0+h)."""
        f = self.face
        Hmat = K @ np.column_stack([R @ f.e_u, R @ f.e_v, R @ f.origin + t])  # face (u, v) mm -> px
        xs, ys = np.meshgrid(np.arange(x0, x0 + w, dtype=np.float64), np.arange(y0, y0 + h, dtype=np.float64))
        uvw = np.linalg.solve(Hmat, np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)]))
        u, v = (uvw[:2] / uvw[2]).reshape(2, h, w)
        ratio = np.ones((h, w))
        for s, (s_tab, r_tab) in zip((v, f.size_u - u, f.size_v - v, u), self.strips, strict=True):
            near = s < self.radius_mm
            # Where two strips meet (near a box corner) their shades multiply: a smooth stand-in
            # for the spherical corner.
            ratio[near] *= np.interp(s[near], s_tab, r_tab)
        return ratio.astype(np.float32)


def _rounded_edges(face: _Face, faces: list[_Face], visible: set[str], camera_centre: np.ndarray,
                   radius_mm: float, light: np.ndarray) -> _RoundedFace:
    """How `face` looks when the box's edges are rounded with `radius_mm`.

    Each edge is worked in its cross-section (2-D, exact: every ray that meets one generator
    line of the cylinder lies in a plane through the camera centre and that line, which cuts the
    face's plane along a line parallel to the edge). Coordinates (m, n): m along the face toward
    the neighbour, n along the face's normal, origin at the sharp edge; the face is n = 0, m < 0
    and the cylinder's axis is at (-r, -r). The arc point at angle a (0: tangent to the face,
    90 degrees: tangent to the neighbour) has normal (sin a, cos a).
    """
    r = radius_mm
    n1 = face.normal
    edges = ((face.origin, -face.e_v), (face.origin + face.size_u * face.e_u, face.e_u),
             (face.origin + face.size_v * face.e_v, face.e_v), (face.origin, -face.e_u))
    a = np.linspace(0.0, math.pi / 2, _ARC_SAMPLES)
    qm, qn = -r + r * np.sin(a), -r + r * np.cos(a)
    silhouette, strips = [], []
    for point, m in edges:
        neighbour = next(g for g in faces if float(np.dot(g.normal, m)) > 0.5)
        cm, cn = float(np.dot(camera_centre - point, m)), float(np.dot(camera_centre - point, n1))
        seen = np.sin(a) * (cm - qm) + np.cos(a) * (cn - qn) > 0
        s = -(cm + cn / (cn - qn) * (qm - cm))  # where the ray through the arc point meets the plane
        if neighbour.name in visible:
            end = int(np.argmax(s < 0)) if np.any(s < 0) else a.size  # the rest is the neighbour's
            s_sil = 0.0
        else:
            end = int(np.argmax(~seen)) if np.any(~seen) else a.size
            s_sil = float(max(s[max(end - 1, 0)], 0.0))
        end = max(end, 2)
        shade = 0.42 + 0.58 * np.maximum(0.0, np.cos(a[:end]) * float(np.dot(n1, light))
                                          + np.sin(a[:end]) * float(np.dot(m, light)))  # as _lambert
        ratio = shade / _lambert(n1, light)
        order = np.argsort(s[:end])
        strips.append((s[:end][order], ratio[order]))
        silhouette.append(s_sil)
    return _RoundedFace(face, tuple(silhouette), tuple(strips), r)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- rendering


def _render(box: Box, K: np.ndarray, R: np.ndarray, t: np.ndarray, image_size: tuple[int, int],
            style: Style, seed: int, photographed: str) -> np.ndarray:
    """The photo (H, W, 3) uint8 RGB of the box seen by camera (K, R, t)."""
    img, rng_noise = _render_linear(box, K, R, t, image_size, style, seed, photographed)
    if style.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), style.blur_sigma, borderType=cv2.BORDER_REFLECT)
    if style.noise_sigma > 0:
        img += rng_noise.standard_normal(img.shape, dtype=np.float32) * np.float32(style.noise_sigma)
    out: np.ndarray = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if style.jpeg_quality is not None:
        out = _jpeg_round_trip(out, style.jpeg_quality)
    return out


def _render_linear(box: Box, K: np.ndarray, R: np.ndarray, t: np.ndarray, image_size: tuple[int, int],
                   style: Style, seed: int, photographed: str, edge_radius_mm: float = 0.0
                   ) -> tuple[np.ndarray, np.random.Generator]:
    """The noiseless, unblurred photo (H, W, 3) float32 RGB 0-255, and the noise generator.

    `edge_radius_mm` > 0 rounds the box's edges (see `_rounded_edges`).
    """
    w, h = int(image_size[0]), int(image_size[1])
    if w < 8 or h < 8:
        raise ValueError(f"image_size must be at least 8x8 px, got {image_size!r}")
    verts = _box_vertices(box)
    if np.min((verts @ R.T + t)[:, 2]) <= 0:
        raise ValueError("the camera is inside or too close to the box: part of it is behind the camera")
    seeds = np.random.SeedSequence(int(seed)).spawn(5)
    rng_color, rng_bg, rng_faces, rng_noise, rng_light = (np.random.default_rng(s) for s in seeds)

    base = _box_color(rng_color, style)
    light = _light(rng_light)
    faces = _faces(box)
    centre = -R.T @ t  # camera centre, world
    visible = {f.name for f in faces if float(np.dot(centre - f.origin, f.normal)) > 1e-9}
    shades = {f.name: _lambert(f.normal, light) for f in faces}
    photographed_color = base * shades[photographed]

    bg = _background(rng_bg, (w, h), style, photographed_color)

    S = _SUPERSAMPLE
    f_px = K[0, 0]
    K_s = np.array([[f_px * S, 0, (K[0, 2] + 0.5) * S - 0.5],
                    [0, f_px * S, (K[1, 2] + 0.5) * S - 0.5], [0, 0, 1.0]])
    acc = np.zeros((h, w, 3), np.float32)  # sum of face colour x coverage
    cover = np.zeros((h, w), np.float32)  # sum of face coverages
    for face in faces:  # every face draws its random numbers, visible or not: stable streams
        rng_face = np.random.default_rng(rng_faces.integers(2**63))
        if face.name not in visible:
            continue
        corners_w = face.corners()
        rounding = None
        if edge_radius_mm > 0:
            rounding = _rounded_edges(face, faces, visible, centre, edge_radius_mm, light)
            corners_w = rounding.silhouette_corners()
        poly = _project(K, R, t, corners_w)
        x0 = max(math.floor(poly[:, 0].min()) - 1, 0)
        y0 = max(math.floor(poly[:, 1].min()) - 1, 0)
        x1 = min(math.ceil(poly[:, 0].max()) + 2, w)
        y1 = min(math.ceil(poly[:, 1].max()) + 2, h)
        if x1 <= x0 or y1 <= y0:
            continue
        # Texture density: _TEXELS_PER_PX at the face's nearest point.
        z_near = float(np.min((corners_w @ R.T + t)[:, 2]))
        mm_per_texel = style.texel_mm or z_near / f_px / _TEXELS_PER_PX
        nu = int(min(_MAX_TEXELS, max(4, math.ceil(face.size_u / mm_per_texel))))
        nv = int(min(_MAX_TEXELS, max(4, math.ceil(face.size_v / mm_per_texel))))
        albedo = np.empty((nv, nu, 3), np.float32)
        albedo[:] = base
        albedo += _grain(rng_face, nv, nu, style.texture)[..., None]
        if style.label and (rng_face.random() < 0.5 or face.name == photographed):
            _draw_label(rng_face, albedo, style.texture)
        tex = albedo * (shades[face.name] * _lighting_field(rng_face, nv, nu, style.lighting))[..., None]
        # Texel (i, j) centre -> face point (u, v) = ((i + 0.5) su, (j + 0.5) sv) -> image.
        su, sv = face.size_u / nu, face.size_v / nv
        plane = np.column_stack([R @ face.e_u * su, R @ face.e_v * sv,
                                 R @ (face.origin + 0.5 * su * face.e_u + 0.5 * sv * face.e_v) + t])
        shift = np.array([[1.0, 0, -S * x0], [0, 1.0, -S * y0], [0, 0, 1.0]])
        Hmat = shift @ K_s @ plane
        big = cv2.warpPerspective(tex, Hmat, ((x1 - x0) * S, (y1 - y0) * S), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REPLICATE)
        colour = cv2.resize(big, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
        if rounding is not None:
            colour *= rounding.shade_ratio(K, R, t, x0, y0, x1 - x0, y1 - y0)[..., None]
        m = _polygon_coverage(poly, x0, y0, x1 - x0, y1 - y0).astype(np.float32)
        acc[y0:y1, x0:x1] += colour * m[..., None]
        cover[y0:y1, x0:x1] += m

    over = cover > 1.0  # only at vertices, where the product coverage is approximate
    acc[over] /= cover[over][:, None]
    cover = np.minimum(cover, 1.0)
    if style.lighting > 0:
        bg = _cast_shadow(bg, cover, R @ light, style.lighting)
    img = bg * (1.0 - cover[..., None]) + acc
    return img, rng_noise


def _cast_shadow(bg: np.ndarray, cover: np.ndarray, light_cam: np.ndarray, lighting: float) -> np.ndarray:
    """Darken the background with a soft shadow of the silhouette, away from the light."""
    ys, xs = np.nonzero(cover > 0.5)
    if xs.size == 0:
        return bg
    size = max(int(np.ptp(xs)), int(np.ptp(ys)), 1)  # px
    away = -light_cam[:2]
    norm = float(np.linalg.norm(away))
    direction = away / norm if norm > 1e-6 else np.array([0.0, 1.0])
    dx, dy = direction * 0.05 * size / 4  # computed at a quarter of the resolution: it is soft
    h, w = cover.shape
    small = cv2.resize(cover, (max(1, w // 4), max(1, h // 4)), interpolation=cv2.INTER_AREA)
    small = cv2.warpAffine(small, np.array([[1.0, 0, dx], [0, 1.0, dy]]), small.shape[::-1])
    small = cv2.GaussianBlur(small, (0, 0), max(0.5, 0.01 * size))
    shadow = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    strength = min(0.35, 0.9 * lighting)
    shaded: np.ndarray = bg * (1.0 - strength * shadow)[..., None]
    return shaded


def _jpeg_round_trip(rgb: np.ndarray, quality: int) -> np.ndarray:
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)  # OpenCV codecs expect BGR
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    decoded = cast("np.ndarray", cv2.imdecode(buf, cv2.IMREAD_COLOR))  # None only for bad bytes
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)


def _scene(box: Box, view: str, image_size: tuple[int, int], focal_px: float, distance_mm: float,
           R: np.ndarray, t: np.ndarray, style: Style, seed: int, names: tuple[str, ...],
           photographed: str, mm_per_px: float | None, side_view: bool = False,
           realism: Realism | None = None, side_face: str = "right") -> Scene:
    K = _camera_matrix(focal_px, _principal(image_size))
    corners = _corners(box)
    if side_face != "right":
        corners.update(_second_face_corners(box, side_face))
    if side_view:
        corners["p3"] = np.array([box.width_mm, box.height_mm, 0.0])  # side lower-left: same corner
    world = np.array([corners[n] for n in names])
    pts = _project(K, R, t, world)
    points = _Points({n: (float(p[0]), float(p[1])) for n, p in zip(names, pts, strict=True)})
    if realism is None:
        image = _render(box, K, R, t, image_size, style, seed, photographed)
        return Scene(image=image, points=points, box=box, focal_px=float(focal_px),
                     distance_mm=float(distance_mm), mm_per_px=mm_per_px, view=view, camera_matrix=K,
                     rotation=R, translation=t)
    dist = realism.distortion()
    seen = distort_points(pts, K, dist)
    image, jpeg = _render_realistic(box, K, R, t, image_size, style, seed, photographed, realism)
    observed = _Points({n: (float(p[0]), float(p[1])) for n, p in zip(names, seen, strict=True)})
    return Scene(image=image, points=observed,
                 box=box, focal_px=float(focal_px), distance_mm=float(distance_mm), mm_per_px=mm_per_px,
                 view=view, camera_matrix=K, rotation=R, translation=t, distortion=dist,
                 pinhole_points=points, jpeg=jpeg)


_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-13)


def distort_points(points: np.ndarray, camera_matrix: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Where a lens with OpenCV `distortion` puts the points an ideal pinhole (same K) puts at `points`.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Pinhole image positions (x, y), px.
    camera_matrix : np.ndarray
        (3, 3) K.
    distortion : np.ndarray
        OpenCV coefficients (k1, k2, p1, p2[, k3...]).

    Returns
    -------
    np.ndarray
        (N, 2) float64 distorted positions, px: OpenCV's forward model (``cv2.projectPoints``).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    K = np.asarray(camera_matrix, dtype=np.float64)
    # Back to normalised rays at unit depth, then projected by OpenCV with the distortion.
    rays = np.column_stack([(pts - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T, np.ones(len(pts))])
    out, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                               np.asarray(distortion, np.float64))
    return out.reshape(-1, 2)


def _undistort_grid(K: np.ndarray, dist: np.ndarray, w: int, h: int) -> np.ndarray:
    """(h, w, 2) float64: the pinhole position of every output pixel centre (OpenCV's inverse
    distortion, iterated to convergence), refusing a distortion that folds the picture."""
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    grid = np.stack([xs, ys], axis=-1).reshape(-1, 1, 2)
    und = cv2.undistortPoints(grid, K, dist, R=None, P=K, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
    # The fixed-point iteration fails silently where the model is not invertible: check the corners.
    corner = np.array([0, w - 1, (h - 1) * w, h * w - 1])
    back = distort_points(und[corner], K, dist)
    miss = float(np.abs(back - grid.reshape(-1, 2)[corner]).max())
    if not (math.isfinite(miss) and miss < 1e-4):
        raise InputError(f"distortion {dist.tolist()!r} is not invertible over a {w}x{h} image "
                         f"(the corners come back {miss:.3g} px away)")
    return und.reshape(h, w, 2)


def _render_realistic(box: Box, K: np.ndarray, R: np.ndarray, t: np.ndarray, image_size: tuple[int, int],
                      style: Style, seed: int, photographed: str, realism: Realism
                      ) -> tuple[np.ndarray, bytes | None]:
    """The `Realism` photo (H, W, 3) uint8 RGB and its JPEG bytes (None without a JPEG quality)."""
    w, h = int(image_size[0]), int(image_size[1])
    if realism.exif is not None and style.jpeg_quality is None:
        raise InputError("Realism.exif needs a JPEG: Style.jpeg_quality is None")
    r = realism.edge_radius_mm
    if r > 0 and 2 * r >= min(box.width_mm, box.height_mm, box.depth_mm):
        raise InputError(f"Realism.edge_radius_mm {r!r} must be less than half the box's smallest "
                         f"side ({box})")
    dist = realism.distortion()
    distorted = bool(np.any(dist != 0))
    ox = oy = 0
    canvas = (w, h)
    if distorted:
        und = _undistort_grid(K, dist, w, h)
        # Barrel distortion shows the pinhole picture beyond the frame: render a canvas that holds it.
        ox = max(0, -math.floor(und[..., 0].min()) + 2)
        oy = max(0, -math.floor(und[..., 1].min()) + 2)
        canvas = (max(w, math.ceil(und[..., 0].max()) + 3) + ox,
                  max(h, math.ceil(und[..., 1].max()) + 3) + oy)
    K_canvas = K.copy()
    K_canvas[0, 2] += ox
    K_canvas[1, 2] += oy
    img, rng_noise = _render_linear(box, K_canvas, R, t, canvas, style, seed, photographed, r)
    if distorted:
        img = cv2.remap(img, (und[..., 0] + ox).astype(np.float32), (und[..., 1] + oy).astype(np.float32),
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    if realism.vignetting > 0:
        img *= vignetting_gain((w, h), realism.vignetting)[..., None]
    if style.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), style.blur_sigma, borderType=cv2.BORDER_REFLECT)
    if style.noise_sigma > 0 or realism.shot_noise > 0:
        sigma = np.sqrt(np.float32(style.noise_sigma) ** 2
                        + np.float32(realism.shot_noise) ** 2 * np.clip(img, 0, 255) / np.float32(255))
        img += rng_noise.standard_normal(img.shape, dtype=np.float32) * sigma
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if style.jpeg_quality is None:
        return out, None
    exif = realism.exif
    data = encode_jpeg(out, style.jpeg_quality, focal_px=float(K[0, 0]) if exif else None,
                       make=exif.make if exif else None, model=exif.model if exif else None)
    return decode_jpeg(data), data


def vignetting_gain(image_size: tuple[int, int], amount: float) -> np.ndarray:
    """(H, W) float32 gain ``1 - amount * rho^2``: 1 at the image centre, ``1 - amount`` at its corners."""
    w, h = int(image_size[0]), int(image_size[1])
    cx, cy = _principal((w, h))
    xs = (np.arange(w, dtype=np.float64) - cx) ** 2
    ys = (np.arange(h, dtype=np.float64) - cy) ** 2
    rho2 = (ys[:, None] + xs[None, :]) / (cx * cx + cy * cy)
    return (1.0 - amount * rho2).astype(np.float32)


_FULL_FRAME_DIAGONAL_MM = 43.2667  # a 36 x 24 mm frame's diagonal: the "35 mm equivalent" reference


def focal_35mm_equivalent(focal_px: float, width: int, height: int) -> float:
    """The 35 mm equivalent focal length, mm, of a focal length in px on a `width` x `height` photo
    (diagonal to diagonal: ``f_px / diagonal_px * 43.2667``)."""
    return float(focal_px) / math.hypot(width, height) * _FULL_FRAME_DIAGONAL_MM


_EXIF_IFD = 0x8769
_TAG_MAKE, _TAG_MODEL, _TAG_ORIENTATION = 0x010F, 0x0110, 0x0112
_TAG_PIXEL_X, _TAG_PIXEL_Y, _TAG_FOCAL_35 = 0xA002, 0xA003, 0xA405


def encode_jpeg(image: np.ndarray, quality: int = 90, *, focal_px: float | None = None,
                make: str | None = None, model: str | None = None) -> bytes:
    """A JPEG file of an (H, W, 3) uint8 RGB image, with the EXIF a phone writes.

    EXIF (written when any of `focal_px`, `make`, `model` is given): Make, Model, Orientation 1,
    PixelXDimension/PixelYDimension (the image's size) and, with `focal_px`,
    FocalLengthIn35mmFilm = round(`focal_35mm_equivalent`) (EXIF stores whole millimetres).
    """
    rgb = np.asarray(image)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {rgb.dtype} {rgb.shape}")
    if not 1 <= int(quality) <= 100:
        raise InputError(f"JPEG quality must be 1-100, got {quality!r}")
    pil = Image.fromarray(np.ascontiguousarray(rgb))
    options: dict[str, object] = {"quality": int(quality)}
    if focal_px is not None or make is not None or model is not None:
        exif = Image.Exif()
        if make is not None:
            exif[_TAG_MAKE] = make
        if model is not None:
            exif[_TAG_MODEL] = model
        exif[_TAG_ORIENTATION] = 1
        sub = exif.get_ifd(_EXIF_IFD)
        sub[_TAG_PIXEL_X] = rgb.shape[1]
        sub[_TAG_PIXEL_Y] = rgb.shape[0]
        if focal_px is not None:
            if not (math.isfinite(focal_px) and focal_px > 0):
                raise InputError(f"focal_px must be positive, got {focal_px!r}")
            sub[_TAG_FOCAL_35] = round(focal_35mm_equivalent(focal_px, rgb.shape[1], rgb.shape[0]))
        options["exif"] = exif.tobytes()
    buf = io.BytesIO()
    pil.save(buf, format="JPEG", **options)
    return buf.getvalue()


def decode_jpeg(data: bytes) -> np.ndarray:
    """(H, W, 3) uint8 RGB pixels of JPEG bytes (Pillow's decoder, as `encode_jpeg`'s)."""
    with Image.open(io.BytesIO(data)) as pil:
        return np.asarray(pil.convert("RGB")).copy()


def _check_camera(image_size: tuple[int, int], focal_px: float, distance_mm: float | None) -> None:
    if len(image_size) != 2 or min(image_size) < 8:
        raise ValueError(f"image_size must be (width, height) of at least 8 px, got {image_size!r}")
    if not (math.isfinite(focal_px) and focal_px > 0):
        raise ValueError(f"focal_px must be positive, got {focal_px!r}")
    if distance_mm is not None and not (math.isfinite(distance_mm) and distance_mm > 0):
        raise ValueError(f"distance_mm must be positive, got {distance_mm!r}")


def _render_square(box: Box, view: str, image_size: tuple[int, int], focal_px: float,
                   distance_mm: float | None, offset_px: tuple[float, float], style: Style,
                   seed: int, realism: Realism | None = None) -> Scene:
    _check_camera(image_size, focal_px, distance_mm)
    face_w = box.width_mm if view == "front" else box.depth_mm
    if distance_mm is None:
        distance_mm = focal_px * max(face_w / (_FILL_WIDTH * image_size[0]),
                                     box.height_mm / (_MAX_FILL_HEIGHT * image_size[1]))
    R, t = _square_pose(box, view, focal_px, distance_mm, offset_px)
    names = ("p1", "p2", "p3", "p6") if view == "front" else ("p4", "p5", "p7", "p3")
    return _scene(box, view, image_size, focal_px, distance_mm, R, t, style, seed, names,
                  "front" if view == "front" else "right", distance_mm / focal_px,
                  side_view=view == "side", realism=realism)


def render_front_view(box: Box, *, image_size: tuple[int, int] = (1280, 1024), focal_px: float = 1400.0,
                      distance_mm: float | None = None, offset_px: tuple[float, float] = (0.0, 0.0),
                      style: Style = DEFAULT_STYLE, seed: int = 0, realism: Realism | None = None) -> Scene:
    """A square photo of the front face (z = 0): its plane is parallel to the image plane.

    Parameters
    ----------
    box : Box
        True size.
    image_size : (int, int)
        (width, height) px; the image has shape (height, width, 3).
    focal_px : float
        Focal length, px. The principal point is the image centre ((w-1)/2, (h-1)/2).
    distance_mm : float or None
        Depth of the front face along the optical axis, mm. None: the face spans about half
        the image width (less if it would then be taller than 3/4 of the image height).
    offset_px : (float, float)
        Where the face's centre projects, relative to the principal point, px.
    style : Style
        Realism settings.
    seed : int
        Seed of all the randomness (colours, textures, label, clutter, noise).
    realism : Realism or None
        Imperfections of real photos (lens distortion, rounded edges, vignetting, shot noise,
        JPEG with EXIF); None renders exactly as before.

    Returns
    -------
    Scene
        ``view="front"``, points p1, p2, p3, p6, ``mm_per_px = distance_mm / focal_px``.
    """
    return _render_square(box, "front", image_size, focal_px, distance_mm, offset_px, style, seed, realism)


def render_side_view(box: Box, *, image_size: tuple[int, int] = (1280, 1024), focal_px: float = 1400.0,
                     distance_mm: float | None = None, offset_px: tuple[float, float] = (0.0, 0.0),
                     style: Style = DEFAULT_STYLE, seed: int = 0, realism: Realism | None = None) -> Scene:
    """A square photo of the side face (x = W), camera at +X looking toward -X.

    Image right is world +Z and image down world +Y, so P4 (z = 0) is on the left and P5
    (z = D) on the right. Parameters as in `render_front_view`, the face being D x H mm.

    Returns
    -------
    Scene
        ``view="side"``, points p4 (W,0,0), p5 (W,0,D), p7 (W,H,D) and p3 (W,H,0), the side
        face's lower-left corner; ``mm_per_px = distance_mm / focal_px``.
    """
    return _render_square(box, "side", image_size, focal_px, distance_mm, offset_px, style, seed, realism)


def render_oblique_view(box: Box, *, image_size: tuple[int, int] = (1280, 1024), focal_px: float = 1400.0,
                        distance_mm: float | None = None, yaw_deg: float = 30.0, pitch_deg: float = 15.0,
                        style: Style = DEFAULT_STYLE, seed: int = 0, realism: Realism | None = None,
                        side_face: str = "right") -> Scene:
    """One photo from the front-right (or -left) and above: the front, a side and the top are visible.

    The camera is aimed at the front face's centre, which projects to the principal point.
    Its centre is at ``c + distance_mm * (sin(yaw) cos(pitch), -sin(pitch), -cos(yaw) cos(pitch))``
    with c the front face's centre, and its x axis is horizontal (perpendicular to world Y).

    Parameters
    ----------
    box : Box
        True size.
    image_size : (int, int)
        (width, height) px.
    focal_px : float
        Focal length, px.
    distance_mm : float or None
        Distance from the camera to the front face's centre (its depth along the optical
        axis), mm. None: the whole box spans about half the image width.
    yaw_deg : float
        Rotation of the camera toward +X (the right side) about the vertical, degrees; negative
        toward the left side.
    pitch_deg : float
        Elevation of the camera above the front face's centre, degrees.
    style : Style
        Realism settings.
    seed : int
        Seed of all the randomness.
    realism : Realism or None
        Imperfections of real photos; None renders exactly as before.
    side_face : {"right", "left", "top"}
        The face p4, p5 and p7 mark besides the front (by role, see `prismcore.geometry.faces`): the
        right side (p4 where p2 is; needs yaw > 0), the left side (p4 where p1 is, p5 and p7
        its far corners; needs yaw < 0) or the top (p4 where p1 is, p5 and p7 its far corners
        above p1 and p2; needs pitch > 0). The image does not depend on it.

    Returns
    -------
    Scene
        ``view="oblique"``, points p1..p7, ``mm_per_px=None``.

    Raises
    ------
    ValueError
        When the camera does not see `side_face` (left or top).
    """
    _check_camera(image_size, focal_px, distance_mm)
    if side_face not in ("right", "left", "top"):
        raise ValueError(f"side_face must be right, left or top, got {side_face!r}")
    if distance_mm is None:
        distance_mm = _auto_distance(box, image_size, focal_px,
                                     lambda d: _oblique_pose(box, d, yaw_deg, pitch_deg))
    R, t = _oblique_pose(box, distance_mm, yaw_deg, pitch_deg)
    centre = -R.T @ t
    seen = {"right": centre[0] > box.width_mm, "left": centre[0] < 0, "top": centre[1] < 0}[side_face]
    # (the right side is not checked: renders from before the choice stay as they were; a camera
    # partly behind the box is the render's to refuse)
    if side_face != "right" and not seen and np.min((_box_vertices(box) @ R.T + t)[:, 2]) > 0:
        raise ValueError(f"a camera at yaw {yaw_deg:g}°, pitch {pitch_deg:g}° does not see the "
                         f"{side_face} face")
    names = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
    return _scene(box, "oblique", image_size, focal_px, distance_mm, R, t, style, seed, names,
                  "front", None, realism=realism, side_face=side_face)


def save_image(scene_or_array: Scene | np.ndarray, path: str | Path) -> None:
    """Write a scene's image (or an (H, W, 3) uint8 RGB array) to `path`.

    The format follows the extension: .png, .jpg/.jpeg (quality 95), .bmp, .tif/.tiff, .webp
    (lossless).

    Raises
    ------
    ValueError
        For another extension or an array that is not (H, W, 3) uint8.
    """
    image = scene_or_array.image if isinstance(scene_or_array, Scene) else np.asarray(scene_or_array)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) uint8 RGB image, got {image.dtype} {image.shape}")
    path = Path(path)
    fmt = _SAVE_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"unsupported image extension {path.suffix!r}: use one of {sorted(_SAVE_FORMATS)}")
    saving: dict[str, dict[str, object]] = {"JPEG": {"quality": 95}, "WEBP": {"lossless": True}}
    options = saving.get(fmt, {})
    Image.fromarray(np.ascontiguousarray(image)).save(path, format=fmt, **options)


# --------------------------------------------------------------------------- photo-like scenes


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

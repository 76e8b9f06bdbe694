"""What a render is of and what it gives: the box (`Box`), its look (`Style`), a phone-like camera's
imperfections (`Realism`, `CameraExif`) and the rendered `Scene` with its exact reference points.
Conventions (pixels, the box frame, the points) are `prismsynth.render`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from prismcore.errors import InputError

__all__ = ["DEFAULT_STYLE", "Box", "CameraExif", "Realism", "Scene", "Style"]


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

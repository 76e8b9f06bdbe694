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

The parts: `models` (Box, Style, Realism, Scene), `box_geometry` (camera, poses, pixel
coverage, rounded edges), `textures` (colours, background, face textures), `phone` (lens
distortion, vignetting, JPEG and EXIF), `photo_like` (whole phone-like scenes from a seed).
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from prismcore.errors import InputError

from .box_geometry import (
    _FILL_WIDTH,
    _MAX_FILL_HEIGHT,
    _auto_distance,
    _box_vertices,
    _camera_matrix,
    _corners,
    _faces,
    _lambert,
    _oblique_pose,
    _polygon_coverage,
    _principal,
    _project,
    _rounded_edges,
    _second_face_corners,
    _square_pose,
)
from .models import DEFAULT_STYLE, Box, Realism, Scene, Style, _Points
from .phone import (
    _jpeg_round_trip,
    _undistort_grid,
    decode_jpeg,
    distort_points,
    encode_jpeg,
    vignetting_gain,
)
from .textures import _background, _box_color, _draw_label, _grain, _light, _lighting_field

__all__ = [
    "render_front_view",
    "render_oblique_view",
    "render_side_view",
    "save_image",
]

_SUPERSAMPLE = 3  # face textures are warped at this many samples per output pixel per axis
_TEXELS_PER_PX = 1.5  # texture density at the face's nearest point, texels per output pixel
_MAX_TEXELS = 3000  # per texture side
_SAVE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP", ".tif": "TIFF",
                 ".tiff": "TIFF", ".webp": "WEBP"}


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



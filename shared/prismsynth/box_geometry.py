"""The box's geometry as a render needs it: the pinhole camera, the box's corners, faces and
vertices, the poses of the square and oblique views, the exact coverage of each pixel by a
projected polygon (anti-aliased, sub-pixel exact edges), and the shading of rounded edges.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .models import Box

__all__: list[str] = []

_FILL_WIDTH = 0.5  # automatic distance: the box spans this fraction of the image width...
_MAX_FILL_HEIGHT = 0.75  # ...unless that makes it taller than this fraction of the height


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


def _lambert(normal: np.ndarray | list[int], light: np.ndarray) -> float:
    return 0.42 + 0.58 * max(0.0, float(np.dot(normal, light)))

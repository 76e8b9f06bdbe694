"""3D assembly: scanned face pixels become world points (x, y, z) with their colours.

World frame: origin at P1 (the front face's upper-left corner), X along P1 -> P2, Y down the
front face (the paper's screen convention), Z into the object; right-handed. The front face
gives X and Y (Z = 0), the side face (at X = width) gives Z and Y, as in the paper. A second face
photographed on the left lands at X = 0, one photographed on top at Y = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from prismcore.errors import InputError
from prismcore.scan.colour_scan import FaceScan

__all__ = ["PREVIEW_POINTS", "Cloud", "assemble", "decimate", "face_points"]

PREVIEW_POINTS = 100_000
"""Points in a display preview: enough for a box's faces to read as surfaces in a 3D view."""


@dataclass(frozen=True)
class Cloud:
    """points: (N, 3) float32 world (x, y, z); colors: (N, 3) uint8 RGB."""

    points: np.ndarray
    colors: np.ndarray


def face_points(
    scan: FaceScan, image: np.ndarray, size: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Map a face's object pixels onto the face rectangle.

    Parameters
    ----------
    scan : FaceScan
    image : ndarray, shape (H, W, 3)
        RGB image the face was scanned in; 8-bit, or 0-255 floats for 16-bit inputs.
    size : (float, float)
        The face's real (horizontal, vertical) size; the face's quad maps onto
        [0, size[0]] x [0, size[1]].

    Returns
    -------
    uv : ndarray, shape (N, 2), float64
        Face coordinates of each object pixel (u right, v down).
    rgb : ndarray, shape (N, 3), uint8
    """
    row0, _, col0, _ = scan.plan.window
    rows, cols = np.nonzero(scan.object_mask)
    target = np.array([[0, 0], [size[0], 0], [size[0], size[1]], [0, size[1]]], dtype=np.float32)
    H = cv2.getPerspectiveTransform(scan.plan.region.astype(np.float32), target).astype(np.float64)
    xy = np.empty((1, rows.size, 2), dtype=np.float64)
    xy[0, :, 0] = cols + col0
    xy[0, :, 1] = rows + row0
    # OpenCV answers None rather than an empty array for no points (a scan that kept no pixel).
    uv = cv2.perspectiveTransform(xy, H)[0] if rows.size else np.empty((0, 2))
    # A flat-index gather is several times faster than boolean-indexing a 3-channel window.
    flat = (rows + row0) * image.shape[1] + (cols + col0)
    rgb = np.take(image.reshape(-1, image.shape[2]), flat, axis=0)
    if rgb.dtype != np.uint8:
        rgb = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    return uv, rgb


def assemble(front: tuple[np.ndarray, np.ndarray], side: tuple[np.ndarray, np.ndarray],
             width: float, depth: float, kind: str, max_points: int, *, side_face: str = "right",
             height: float | None = None) -> Cloud:
    """Build the cloud of the prism.

    Parameters
    ----------
    front, side : (uv, rgb)
        Output of :func:`face_points` for each face, the side's quad as photographed: a right
        side's u runs along the depth from the front (Z = u), a left side's toward it
        (Z = depth - u); a top's u runs along X and its v toward the front (Z = depth - v).
    width, depth : float
        Real width (X) and depth (Z) of the prism.
    kind : {"surface", "volume"}
        `surface`: the prism's six faces: the front and the second face as seen, the back and
        the face opposite the second one as their copies (at Z = depth; at X = 0 for a right
        side, X = width for a left one, Y = height for a top), and the two faces left from the
        front's first and last rows (columns for a top face) carried through every depth step.
        `volume`: every front pixel at every depth step (the paper's cloud).
    max_points : int
        Refuse (InputError) a cloud larger than this before allocating it.
    side_face : {"right", "left", "top"}
        Where the second face was photographed.
    height : float, optional
        Real height (Y) of the prism; needed for a top face (its copy is the bottom).
    """
    if side_face not in ("right", "left", "top"):
        raise ValueError(f"side_face must be right, left or top, got {side_face!r}")
    if side_face == "top" and height is None:
        raise ValueError("a top face needs the prism's height (its copy is the bottom face)")
    (f_uv, f_rgb), (s_uv, s_rgb) = front, side
    pitch = _pitch(f_uv)
    if f_uv.shape[0] < 2:
        zs = np.array([0.0, depth])
    else:
        zs = np.linspace(0.0, depth, max(2, round(depth / max(pitch or width, 1e-12)) + 1))
    if kind == "volume":
        n = f_uv.shape[0] * zs.size
        _check_size(n, max_points, kind)
        pts = np.empty((zs.size, f_uv.shape[0], 3), dtype=np.float32)
        pts[..., :2] = f_uv
        pts[..., 2] = zs[:, None]
        return Cloud(pts.reshape(-1, 3), np.tile(f_rgb, (zs.size, 1)))
    first, last = _edge_rows(f_uv, pitch or 1.0, 0 if side_face == "top" else 1)
    layers = [(f_uv[first], f_rgb[first]), (f_uv[last], f_rgb[last])]
    n = 2 * len(f_uv) + 2 * len(s_uv) + sum(len(uv) for uv, _ in layers) * zs.size
    _check_size(int(n), max_points, kind)
    # Every face written straight into the cloud's arrays (no parts joined afterwards).
    points = np.empty((int(n), 3), dtype=np.float32)
    colors = np.empty((int(n), 3), dtype=np.uint8)
    at = 0

    def face(x: np.ndarray | float, y: np.ndarray | float, z: np.ndarray | float, rgb: np.ndarray) -> None:
        nonlocal at
        block = points[at:at + len(rgb)]
        block[:, 0], block[:, 1], block[:, 2] = x, y, z
        colors[at:at + len(rgb)] = rgb
        at += len(rgb)

    f32 = f_uv.astype(np.float32)
    s32 = s_uv.astype(np.float32)
    face(f32[:, 0], f32[:, 1], 0.0, f_rgb)  # front
    face(f32[:, 0], f32[:, 1], depth, f_rgb)  # back
    if side_face == "right":
        face(width, s32[:, 1], s32[:, 0], s_rgb)  # right side, as seen
        face(0.0, s32[:, 1], s32[:, 0], s_rgb)  # left side
    elif side_face == "left":
        z = np.float32(depth) - s32[:, 0]
        face(0.0, s32[:, 1], z, s_rgb)  # left side, as seen
        face(width, s32[:, 1], z, s_rgb)  # right side
    else:
        assert height is not None  # a top face's height was checked on entry
        z = np.float32(depth) - s32[:, 1]
        face(s32[:, 0], 0.0, z, s_rgb)  # top, as seen
        face(s32[:, 0], height, z, s_rgb)  # bottom
    for uv, rgb in layers:  # top and bottom (left and right beside a top face), at every depth step
        count = zs.size * len(uv)
        block = points[at:at + count].reshape(zs.size, len(uv), 3)
        block[..., :2] = uv
        block[..., 2] = zs[:, None]
        colors[at:at + count].reshape(zs.size, len(uv), 3)[:] = rgb
        at += count
    return Cloud(points, colors)


def _pitch(front_uv: np.ndarray) -> float:
    """Spacing of the front pixels on the face (0 for fewer than 2 points or a single row or
    column); the depth steps and the top and bottom rows both go by it."""
    if front_uv.shape[0] < 2:
        return 0.0
    extent = np.ptp(front_uv[:, 0]) * np.ptp(front_uv[:, 1])
    return float(np.sqrt(extent / front_uv.shape[0]))


def _edge_rows(front_uv: np.ndarray, pitch: float, axis: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the front points on the face's first and last pixel rows (axis 1: nearest v,
    top and bottom) or columns (axis 0: nearest u, left and right)."""
    if front_uv.shape[0] == 0:
        empty = np.zeros(0, dtype=bool)
        return empty, empty
    v = front_uv[:, axis]
    return v <= v.min() + 0.5 * pitch, v >= v.max() - 0.5 * pitch


def _check_size(n: int, max_points: int, kind: str) -> None:
    if n > max_points:
        raise InputError(
            f"the {kind} cloud would have {n:,} points, over the limit of {max_points:,}; "
            "use cloud=surface or raise max_points"
        )


def decimate(cloud: Cloud, max_points: int = PREVIEW_POINTS) -> Cloud:
    """At most `max_points` points of `cloud`, evenly spread over its point order, for display.

    Deterministic (the same cloud gives the same preview: the worker may write it twice), and
    scan order is row order per face, so an even stride keeps every face's coverage uniform.
    Returns `cloud` itself when it is small enough; never modifies it.
    """
    if max_points < 1:
        raise InputError(f"max_points must be at least 1, got {max_points}")
    n = len(cloud.points)
    if n <= max_points:
        return cloud
    keep = (np.arange(max_points, dtype=np.int64) * n) // max_points
    return Cloud(cloud.points[keep], cloud.colors[keep])

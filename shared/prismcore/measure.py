"""Real dimensions of the prism from its refined face quads and the scale the user gave.

Two models:

* affine (the paper's): each face is taken as photographed squarely, so its size is its
  pixel size times a millimetres-per-pixel scale;
* perspective (needs the focal length and all four corners of each face): the box's pose and
  proportions are fitted to the corners through a pinhole camera, and the scale fixes its size.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .perspective import FaceEvidence, fit_box, fit_rectangle
from .spec import KnownEdge, MmPerPx, Pinhole, Scale

__all__ = ["Dimensions", "camera_matrix", "measure_affine", "measure_perspective", "quad_size_px"]

@dataclass(frozen=True)
class Dimensions:
    """Width (X), height (Y) and depth (Z) of the prism, in `unit` ("mm" or "px")."""

    width: float
    height: float
    depth: float
    unit: str
    perspective: bool
    notes: tuple[str, ...] = field(default=())


def quad_size_px(quad: np.ndarray) -> tuple[float, float]:
    """Mean lengths (px) of the horizontal and of the vertical sides of a TL, TR, BR, BL quad."""
    sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
    return float((sides[0] + sides[2]) / 2), float((sides[1] + sides[3]) / 2)


def camera_matrix(focal_px: float, principal: tuple[float, float]) -> np.ndarray:
    """Pinhole intrinsics K, shape (3, 3), for square pixels."""
    return np.array([[focal_px, 0, principal[0]], [0, focal_px, principal[1]], [0, 0, 1.0]])


def _scales_affine(scale: Scale | None, sizes: dict[str, float], focal: float | None,
                   two_photo: bool) -> tuple[float | None, float | None, str]:
    front = side = None
    unit = "mm"
    if isinstance(scale, MmPerPx):
        front, side = scale.front, scale.side
    elif isinstance(scale, Pinhole):
        assert focal is not None  # the spec's validator demands it
        front = scale.distance_mm / focal
        side = scale.side_distance_mm / focal if scale.side_distance_mm else None
    elif isinstance(scale, KnownEdge):
        measured = {"width": sizes["w"], "height": sizes["h"], "depth": sizes["d"]}[scale.edge]
        if scale.edge == "depth":
            side = scale.length_mm / measured
        else:
            front = scale.length_mm / measured
    else:
        front, unit = 1.0, "px"
    if not two_photo:
        front = front or side
        side = side or front
    return front, side, unit


def measure_affine(front: np.ndarray, side: np.ndarray, scale: Scale | None, *,
                   focal_px: float | None, two_photo: bool) -> Dimensions:
    """Dimensions with each face assumed square to the camera (the paper's model)."""
    w_px, h_px = quad_size_px(front)
    d_px, hs_px = quad_size_px(side)
    s_front, s_side, unit = _scales_affine(scale, {"w": w_px, "h": h_px, "d": d_px},
                                           focal_px, two_photo)
    notes = []
    # Two photos, one scale: the face height both photos show carries it across.
    if s_front is None and s_side is not None:
        s_front = s_side * hs_px / h_px
        notes.append("front scale derived from the side photo through the shared height")
    if s_side is None and s_front is not None:
        s_side = s_front * h_px / hs_px
        notes.append("side scale derived from the front photo through the shared height")
    assert s_front is not None and s_side is not None
    return Dimensions(w_px * s_front, h_px * s_front, d_px * s_side, unit, False, tuple(notes))


def _centre_depth(rvec: np.ndarray, tvec: np.ndarray, width: float) -> float:
    R = cv2.Rodrigues(rvec)[0]
    return float((R @ np.array([width / 2, 0.5, 0.0]) + tvec)[2])


def measure_perspective(front: FaceEvidence, side: FaceEvidence, scale: Scale | None, *,
                        K_front: np.ndarray, K_side: np.ndarray, two_photo: bool
                        ) -> tuple[Dimensions, np.ndarray, np.ndarray]:
    """Dimensions with perspective corrected through a pinhole camera of known focal length.

    The shooting distance (or mm-per-pixel, read as distance / focal) is the depth of the front
    face's centre along the optical axis.

    Returns
    -------
    dimensions : Dimensions
    front_quad, side_quad : ndarray, shape (4, 2)
        The faces' corners as the fitted model projects them.
    """
    if two_photo:
        width, rvec, tvec, front_quad = fit_rectangle(K_front, front)
        depth, _, _, side_quad = fit_rectangle(K_side, side)
    else:
        width, depth, rvec, tvec, front_quad, side_quad = fit_box(K_front, front, side)
    z = _centre_depth(rvec, tvec, width)
    focal = float(K_front[0, 0])
    unit = "mm"
    if isinstance(scale, Pinhole):
        k = scale.distance_mm / z
    elif isinstance(scale, MmPerPx):
        k = scale.front * focal / z
    elif isinstance(scale, KnownEdge):
        k = scale.length_mm / {"width": width, "height": 1.0, "depth": depth}[scale.edge]
    else:
        k, unit = focal / z, "px"  # pixels at the front face centre's depth
    return Dimensions(width * k, k, depth * k, unit, True), front_quad, side_quad

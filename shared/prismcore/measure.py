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
from scipy.optimize import least_squares

from .spec import KnownEdge, MmPerPx, Pinhole, Scale

__all__ = ["Dimensions", "camera_matrix", "fit_box", "fit_rectangle", "measure_affine",
           "measure_perspective", "quad_size_px"]

_UNIT_SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64)


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


def _project(K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, pts: np.ndarray) -> np.ndarray:
    R = cv2.Rodrigues(rvec)[0]
    cam = pts @ R.T + tvec
    uv = cam @ K.T
    return uv[:, :2] / uv[:, 2:3]


def fit_rectangle(K: np.ndarray, quad: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Aspect (width / height) and pose of a rectangle seen as `quad`, with its height = 1.

    Returns
    -------
    aspect : float
    rvec, tvec : ndarray, shape (3,)
        Pose of the rectangle's frame (origin TL, x along the top, y down the left side).
    """
    H = cv2.getPerspectiveTransform(_UNIT_SQUARE.astype(np.float32), quad.astype(np.float32))
    M = np.linalg.solve(K, H)
    if M[2, 2] < 0:  # the plane must lie in front of the camera
        M = -M
    a1, a2, a3 = M.T
    lam = np.linalg.norm(a2)
    aspect = float(np.linalg.norm(a1) / lam)
    r1, r2 = a1 / np.linalg.norm(a1), a2 / lam
    U, _, Vt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=1))
    R = U @ Vt
    rvec0, tvec0 = cv2.Rodrigues(R)[0].ravel(), a3 / lam

    def residual(x: np.ndarray) -> np.ndarray:
        corners = np.array([[0, 0, 0], [x[6], 0, 0], [x[6], 1, 0], [0, 1, 0]], dtype=np.float64)
        return (_project(K, x[:3], x[3:6], corners) - quad).ravel()

    fit = least_squares(residual, np.concatenate([rvec0, tvec0, [aspect]]), method="lm")
    return float(fit.x[6]), fit.x[:3], fit.x[3:6]


def fit_box(K: np.ndarray, front: np.ndarray, side: np.ndarray):
    """Width and depth (height = 1) and pose of a box whose front and right side are in one photo.

    The front's corners are (0,0,0), (W,0,0), (W,1,0), (0,1,0) and the side's (W,0,0), (W,0,D),
    (W,1,D), (W,1,0) in the box frame (X right, Y down, Z into the object).
    """
    width, rvec, tvec = fit_rectangle(K, front)
    depth, _, _ = fit_rectangle(K, side)
    observed = np.concatenate([front, side])

    def residual(x: np.ndarray) -> np.ndarray:
        W, D = x[6], x[7]
        corners = np.array([[0, 0, 0], [W, 0, 0], [W, 1, 0], [0, 1, 0],
                            [W, 0, 0], [W, 0, D], [W, 1, D], [W, 1, 0]], dtype=np.float64)
        return (_project(K, x[:3], x[3:6], corners) - observed).ravel()

    fit = least_squares(residual, np.concatenate([rvec, tvec, [width, depth]]), method="lm")
    return float(fit.x[6]), float(fit.x[7]), fit.x[:3], fit.x[3:6]


def _centre_depth(rvec: np.ndarray, tvec: np.ndarray, width: float) -> float:
    R = cv2.Rodrigues(rvec)[0]
    return float((R @ np.array([width / 2, 0.5, 0.0]) + tvec)[2])


def measure_perspective(front: np.ndarray, side: np.ndarray, scale: Scale | None, *,
                        K_front: np.ndarray, K_side: np.ndarray, two_photo: bool) -> Dimensions:
    """Dimensions with perspective corrected through a pinhole camera of known focal length.

    The shooting distance (or mm-per-pixel, read as distance / focal) is the depth of the front
    face's centre along the optical axis.
    """
    if two_photo:
        width, rvec, tvec = fit_rectangle(K_front, front)
        depth, _, _ = fit_rectangle(K_side, side)
    else:
        width, depth, rvec, tvec = fit_box(K_front, front, side)
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
    return Dimensions(width * k, k, depth * k, unit, True)

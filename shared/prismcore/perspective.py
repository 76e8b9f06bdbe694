"""Pinhole fits of a rectangle or a box to the fitted edge lines of its faces.

Corners found by intersecting fitted lines are ill-conditioned when two sides meet at a small
angle (a side face seen nearly edge-on). So the model is fitted to the lines themselves: each
model edge's projected end points must lie on its fitted line (sigma 0.3 px), and each model
corner is pulled weakly towards its click (sigma 5 px), which only decides what the lines leave
open. Sides where no edge was found contribute through the clicks alone; a side fitted to the
wrong edge is outvoted by the others through a robust (Cauchy) loss.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

__all__ = ["FaceEvidence", "fit_box", "fit_rectangle", "project"]

SIGMA_LINE_PX = 0.3
SIGMA_CLICK_PX = 5.0
_UNIT_SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32)


@dataclass(frozen=True)
class FaceEvidence:
    """What the image says about one face.

    corners : (4, 2) TL, TR, BR, BL image (x, y) px, from intersecting the fitted lines
    clicked : (4, 2) the same corners as clicked
    lines : four (a, b, c) lines (top, right, bottom, left), None where no edge was found
    """

    corners: np.ndarray
    clicked: np.ndarray
    lines: tuple[np.ndarray | None, ...]


def project(K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Project world points (N, 3) to image (x, y) px, shape (N, 2)."""
    cam = pts @ cv2.Rodrigues(rvec)[0].T + tvec
    uv = cam @ K.T
    return uv[:, :2] / uv[:, 2:3]


def _closed_form(K: np.ndarray, quad: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Aspect and pose (height 1) of a rectangle imaged as `quad`, from its homography."""
    H = cv2.getPerspectiveTransform(_UNIT_SQUARE, quad.astype(np.float32))
    M = np.linalg.solve(K, H)
    if M[2, 2] < 0:  # the plane must lie in front of the camera
        M = -M
    a1, a2, a3 = M.T
    lam = np.linalg.norm(a2)
    r1, r2 = a1 / np.linalg.norm(a1), a2 / lam
    U, _, Vt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=1))
    return float(np.linalg.norm(a1) / lam), cv2.Rodrigues(U @ Vt)[0].ravel(), a3 / lam


def _solve(K: np.ndarray, corners_of: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
           faces: list[tuple[FaceEvidence, tuple[int, ...], tuple[int, ...]]]) -> np.ndarray:
    """Least squares over pose (rvec, tvec) and shape parameters x0[6:].

    faces: (evidence, model corner index of TL, TR, BR, BL, sides of the face to use).
    """
    def residual(x: np.ndarray) -> np.ndarray:
        pts = project(K, x[:3], x[3:6], corners_of(x[6:]))
        out = []
        for face, idx, sides in faces:
            quad = pts[list(idx)]
            for s in sides:
                line = face.lines[s]
                if line is not None:
                    ends = quad[[s, (s + 1) % 4]]
                    out.append((ends @ line[:2] + line[2]) / SIGMA_LINE_PX)
            out.append(((quad - face.clicked) / SIGMA_CLICK_PX).ravel())
        return np.concatenate(out)

    # A robust loss: one side fitted to the wrong edge (it happens on a face seen nearly
    # edge-on) must not drag the box, which the other sides and the clicks hold in place.
    return least_squares(residual, x0, method="trf", x_scale="jac", loss="cauchy",
                         f_scale=3.0).x


def fit_rectangle(K: np.ndarray, face: FaceEvidence):
    """Aspect (width / height) and pose of a rectangle, its height = 1.

    Returns
    -------
    aspect : float
    rvec, tvec : ndarray, shape (3,)
    quad : ndarray, shape (4, 2)
        The fitted rectangle's projected corners.
    """
    aspect, rvec, tvec = _closed_form(K, face.corners)

    def corners_of(p: np.ndarray) -> np.ndarray:
        return np.array([[0, 0, 0], [p[0], 0, 0], [p[0], 1, 0], [0, 1, 0]], dtype=np.float64)

    x = _solve(K, corners_of, np.concatenate([rvec, tvec, [aspect]]),
               [(face, (0, 1, 2, 3), (0, 1, 2, 3))])
    return float(x[6]), x[:3], x[3:6], project(K, x[:3], x[3:6], corners_of(x[6:]))


def fit_box(K: np.ndarray, front: FaceEvidence, side: FaceEvidence):
    """Width and depth (height = 1) and pose of a box whose front and right side share a photo.

    Model corners: P1 (0,0,0), P2 (W,0,0), P3 (W,1,0), P6 (0,1,0), P5 (W,0,D), P7 (W,1,D)
    (X right, Y down, Z into the object). The side's left side is the front's right side, so
    it is used once.

    Returns
    -------
    width, depth : float
    rvec, tvec : ndarray, shape (3,)
    front_quad, side_quad : ndarray, shape (4, 2)
    """
    width, rvec, tvec = _closed_form(K, front.corners)
    depth = _closed_form(K, side.corners)[0]

    def corners_of(p: np.ndarray) -> np.ndarray:
        W, D = p
        return np.array([[0, 0, 0], [W, 0, 0], [W, 1, 0], [0, 1, 0], [W, 0, D], [W, 1, D]],
                        dtype=np.float64)

    front_idx, side_idx = (0, 1, 2, 3), (1, 4, 5, 2)
    x = _solve(K, corners_of, np.concatenate([rvec, tvec, [width, depth]]),
               [(front, front_idx, (0, 1, 2, 3)), (side, side_idx, (0, 1, 2))])
    pts = project(K, x[:3], x[3:6], corners_of(x[6:]))
    return float(x[6]), float(x[7]), x[:3], x[3:6], pts[list(front_idx)], pts[list(side_idx)]

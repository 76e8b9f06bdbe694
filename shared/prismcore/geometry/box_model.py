"""The photo fit's box model: where each corner of a box lies (height 1, width W, depth D) and
which corners each face's quad marks, for the front and each second face (right, left or top),
and the pinhole camera matrix the fits project through.

The single photo's fit (`prismcore.geometry.perspective`), what it leaves out
(`prismcore.geometry.model_error`) and the joint fit of several views (`prismcore.multiview`)
all read the same table, `SECOND_FACES`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "FRONT_IDX",
    "SECOND_FACES",
    "SIDE_AXES",
    "SIDE_IDX",
    "SecondFace",
    "camera_matrix",
    "left_corners",
    "right_corners",
    "top_corners",
]


def camera_matrix(focal: float, principal: np.ndarray) -> np.ndarray:
    """The pinhole K of a focal length (px, square pixels) about a principal point (px)."""
    return np.array([[focal, 0, principal[0]], [0, focal, principal[1]], [0, 0, 1.0]])


def right_corners(p: np.ndarray) -> np.ndarray:
    """The six corners (6, 3) of a box of shape p = (W, D), height 1, whose second face is the
    right side (the paper's) in the plane X = W."""
    W, D = p[0], p[1]
    return np.array([[0, 0, 0], [W, 0, 0], [W, 1, 0], [0, 1, 0], [W, 0, D], [W, 1, D]],
                    dtype=np.float64)


def left_corners(p: np.ndarray) -> np.ndarray:
    """The six corners (6, 3) of a box of shape p = (W, D), height 1, whose second face is the
    left side in the plane X = 0."""
    W, D = p[0], p[1]
    return np.array([[0, 0, 0], [W, 0, 0], [W, 1, 0], [0, 1, 0], [0, 0, D], [0, 1, D]],
                    dtype=np.float64)


def top_corners(p: np.ndarray) -> np.ndarray:
    """The six corners (6, 3) of a box of shape p = (W, D), height 1, whose second face is the
    top in the plane Y = 0."""
    W, D = p[0], p[1]
    return np.array([[0, 0, 0], [W, 0, 0], [W, 1, 0], [0, 1, 0], [0, 0, D], [W, 0, D]],
                    dtype=np.float64)


FRONT_IDX, SIDE_IDX = (0, 1, 2, 3), (1, 4, 5, 2)
# World (X, Y, Z) -> the side rectangle's own frame (u along Z, v along Y, w = W - X).
SIDE_AXES = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class SecondFace:
    """Where a second face lies on the box model.

    corners : the model's six corners (P1, P2, P3, P6, P5, P7) of (W, D), height 1
    idx : the model corners of the side quad's TL, TR, BR, BL as photographed
    sides : the side quad's edges fitted (all but the one shared with the front)
    axes : world -> the side rectangle's frame (rows: its u, v and u x v directions)
    origin : its TL corner in the world, as a function of (W, D)
    v_is_depth : its TL -> BL edge is the depth D (else the height, 1)
    """

    corners: Callable[[np.ndarray], np.ndarray]
    idx: tuple[int, ...]
    sides: tuple[int, ...]
    axes: np.ndarray
    origin: Callable[[float, float], np.ndarray]
    v_is_depth: bool


SECOND_FACES = {
    "right": SecondFace(right_corners, SIDE_IDX, (0, 1, 2), SIDE_AXES,
                     lambda w, d: np.array([w, 0.0, 0.0]), False),
    "left": SecondFace(left_corners, (4, 0, 3, 5), (0, 2, 3),
                    np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
                    lambda w, d: np.array([0.0, 0.0, d]), False),
    "top": SecondFace(top_corners, (4, 5, 1, 0), (0, 1, 3),
                   np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
                   lambda w, d: np.array([0.0, 0.0, d]), True),
}

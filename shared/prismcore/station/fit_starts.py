"""Where the box fit starts: boxes guessed from the silhouette cast onto the support.

The silhouette alone has local minima (the box turned a quarter with its sides swapped, a tall
box on a small footprint against a low one on a large footprint): the fit starts from many.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["starting_boxes"]


def starting_boxes(outline: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Starting boxes (x, y, yaw rad, log L, log W, log H) for the fit of a box resting on the plane
    z = 0 to its silhouette: the outline (N, 2) px cast onto the support, its smallest rectangle
    shrunk, at a few heights and turns. K : (3, 3); R, t : the plane's pose (board -> camera)."""
    rays = np.column_stack([(outline - (K[0, 2], K[1, 2])) / (K[0, 0], K[1, 1]), np.ones(len(outline))])
    rays_b = rays @ R  # board frame directions (R.T @ ray for each)
    centre = -R.T @ t
    s = -centre[2] / rays_b[:, 2]
    ground = centre[:2] + s[:, None] * rays_b[:, :2]
    (cx, cy), (w, h), ang = cv2.minAreaRect(ground.astype(np.float32))
    starts = []
    for shrink, height, turn in (
        (a, b, c) for a in (0.85, 0.6) for b in (0.3, 0.7, 1.4) for c in (0, 15, 30, 45, 60, 75)
    ):
        L, W = max(w * shrink, 1.0), max(h * shrink, 1.0)
        H = max(height * np.sqrt(w * h) * shrink, 1.0)
        # the footprint lies towards the camera's side of the cast outline
        toward = centre[:2] - (cx, cy)
        toward = toward / (np.linalg.norm(toward) + 1e-9) * (1 - shrink) * 0.5 * max(w, h)
        starts.append(
            np.array(
                [cx + toward[0], cy + toward[1], np.radians(ang + turn), np.log(L), np.log(W), np.log(H)]
            )
        )
    return starts

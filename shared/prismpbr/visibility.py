"""What of the board a scene shows, from its truth: how many of the board's inner corners a
detector could find at best, the part and the photo's edges allowing. A hand-held photo whose
part hides the board asks the impossible (a part larger than its board, laid over it): the
benchmark counts such scenes apart, beside the figures over all scenes."""

from __future__ import annotations

import cv2
import numpy as np

from .layout import Scene

__all__ = ["board_corners_shown"]


def board_corners_shown(scene: Scene) -> int:
    """The board's inner corners that show in `scene`'s photo: the corner and the centres of
    the four squares round it (a ChArUco corner is read through the markers beside it) within
    the image, half a square from its edge, and outside the part's silhouette (the convex hull
    of its eight corners). Clutter is not counted as hiding anything."""
    board, cam = scene.board, scene.camera
    w, h = cam.size
    pts = board.corner_points()
    half = board.square_mm / 2
    shifts = [np.array([dx, dy, 0.0]) for dx in (-half, half) for dy in (-half, half)]
    probes = np.vstack([pts, *(pts + s for s in shifts)])
    px = cam.project(probes).reshape(5, len(pts), 2)
    margin = half * cam.K[0, 0] / max(float(np.linalg.norm(cam.t)), 1.0)
    inside = ((px >= margin) & (px < np.array([w, h]) - margin)).all(axis=2).all(axis=0)
    if scene.part is not None:
        hull = cv2.convexHull(cam.project(scene.part.corners()).astype(np.float32))
        for j in np.flatnonzero(inside):
            if any(cv2.pointPolygonTest(hull, (float(x), float(y)), False) >= 0 for x, y in px[:, j]):
                inside[j] = False
    return int(inside.sum())

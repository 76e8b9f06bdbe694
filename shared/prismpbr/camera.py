"""The camera: an OpenCV pinhole with lens distortion, rendered by Mitsuba as an ideal pinhole
on a larger canvas and resampled through the distortion afterwards, as a real lens bends light
before the sensor samples it.

Conventions are OpenCV's and the engine's: the camera looks along +z, x right, y down; image
points (x, y) have their origin at the top-left pixel's centre. The world is the board's frame
(x along the board's width, y along its height, z into the table: heights are negative z).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["LensCamera", "look_at"]


def look_at(centre: np.ndarray, target: np.ndarray, roll_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """World -> camera rotation and translation for a camera at `centre` aimed at `target`.

    The image's "down" is the world's +z projected (towards the table), then rolled about the
    viewing axis by `roll_deg`. Returns (R (3, 3), t (3,)) with x_cam = R x_world + t.
    """
    z = np.asarray(target, float) - np.asarray(centre, float)
    z /= np.linalg.norm(z)
    down = np.array([0.0, 0.0, 1.0])
    y = down - (down @ z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    x, y = c * x + s * y, -s * x + c * y
    R = np.vstack([x, y, z])
    return R, -R @ np.asarray(centre, float)


@dataclass(frozen=True)
class LensCamera:
    """Intrinsics K (3, 3), OpenCV distortion (5,), pose R (3, 3), t (3,), image size (w, h)."""

    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    size: tuple[int, int]

    @property
    def centre(self) -> np.ndarray:
        """The camera's centre in the world, (3,) mm."""
        return np.asarray(-self.R.T @ self.t, float)

    def project(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) -> distorted image points (N, 2), (x, y) px."""
        rvec, _ = cv2.Rodrigues(self.R)
        pts, _ = cv2.projectPoints(
            np.asarray(X, np.float64).reshape(-1, 1, 3), rvec, self.t, self.K, self.dist
        )
        return pts.reshape(-1, 2)

    def render_plan(self) -> tuple[int, int, float, np.ndarray, np.ndarray]:
        """The ideal pinhole canvas to render and the map that resamples it into the photo.

        Returns (width, height, horizontal fov in degrees, map_x, map_y): the canvas's optical
        axis is at its centre, its pixels square with K's fx as focal length; map_x, map_y
        (h, w) float32 give, for each photo pixel, where its ray meets the canvas.
        """
        w, h = self.size
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
        ideal = cv2.undistortPoints(
            pts,
            self.K,
            self.dist,
            None,
            None,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9),
        ).reshape(-1, 2)
        f = float(self.K[0, 0])
        reach_x = float(np.abs(ideal[:, 0]).max()) * f + 3
        reach_y = float(np.abs(ideal[:, 1]).max()) * f + 3
        cw, ch = 2 * int(np.ceil(reach_x)), 2 * int(np.ceil(reach_y))
        # Mitsuba's pixel i spans [i, i + 1): its centre, OpenCV's i, lies at i + 0.5, so the
        # canvas's optical axis (its middle, cw / 2) is at OpenCV x = cw / 2 - 0.5.
        map_x = (ideal[:, 0] * f + cw / 2 - 0.5).reshape(h, w).astype(np.float32)
        map_y = (ideal[:, 1] * f + ch / 2 - 0.5).reshape(h, w).astype(np.float32)
        fov = float(np.degrees(2 * np.arctan(cw / 2 / f)))
        return cw, ch, fov, map_x, map_y

    def mitsuba_to_world(self) -> np.ndarray:
        """The sensor's to_world (4, 4): Mitsuba's camera looks along +z with x to the left and
        y up, OpenCV's along +z with x right and y down."""
        M = np.eye(4)
        M[:3, :3] = self.R.T @ np.diag([-1.0, -1.0, 1.0])
        M[:3, 3] = self.centre
        return M

"""The station's part with rounded edges: the radius read from the shading across its folds.

A box's rounded edges pull its silhouette in (the camera's ray grazes the rounding inside the
sharp edge: by 0.41 radii across an edge seen at 45 degrees), so a sharp box fitted to the outline
is short by about a radius on every side (a 2.3 mm rounding: -1.0, -1.5, -1.0 mm on a 22 mm
carton, in path-traced renders). The radius is read where two faces the camera sees meet (the
engine's `geometry.rounding`, the click mode's reading) and the box refitted with it
(`boxfit.fit_outline_box(radius_mm=...)`).
"""

from __future__ import annotations

import numpy as np

from prismcore.geometry.rounding import RadiusEstimate, estimate_edge_radius
from prismcore.station.boxfit import OutlineFit, project

__all__ = ["edge_radius"]


def edge_radius(photo_u: np.ndarray, fit: OutlineFit, K: np.ndarray, R: np.ndarray, t: np.ndarray
                ) -> RadiusEstimate | None:
    """The radius of the fitted box's rounded edges from the undistorted photo `photo_u`
    (H, W, 3), or None where its folds show no rounding (too few, too small, or sharp).

    fit : the box fitted sharp; K (3, 3), R (3, 3), t (3,) mm: the support's pose (board -> camera).
    """
    X = fit.corners()
    origin = X[0]
    ex, ey = X[1] - X[0], X[3] - X[0]
    size = np.array([np.linalg.norm(ex), np.linalg.norm(ey), fit.height_mm])
    # the box's own frame: along its length, its width, and up from the support (board z is down)
    axes = np.column_stack([ex / size[0], ey / size[1], np.array([0.0, 0.0, -1.0])])

    def to_image(P: np.ndarray) -> np.ndarray:
        return project(origin + np.asarray(P, np.float64) @ axes.T, K, R, t)

    camera = axes.T @ (-R.T @ t - origin)
    return estimate_edge_radius(photo_u, to_image, size, camera)

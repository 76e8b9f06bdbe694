"""The geometry of a box in a photo: face quadrilaterals from the points, sub-pixel edges, pinhole
fits of a rectangle or a box (focal length, distortion), rounded edges, chessboard calibration.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "BoxFit",
    "Calibration",
    "EdgeFit",
    "FaceQuads",
    "RadiusEstimate",
    "calibrate",
    "calibrate_images",
    "clicked_quads",
    "estimate_edge_radius",
    "find_board",
    "fit_box",
    "fit_rectangle",
    "refine_quad",
    "validate_points",
]

_EXPORTS = {
    "BoxFit": "perspective",
    "Calibration": "calibration",
    "EdgeFit": "edges",
    "FaceQuads": "faces",
    "RadiusEstimate": "rounding",
    "calibrate": "calibration",
    "calibrate_images": "calibration",
    "clicked_quads": "faces",
    "estimate_edge_radius": "rounding",
    "find_board": "calibration",
    "fit_box": "perspective",
    "fit_rectangle": "perspective",
    "refine_quad": "edges",
    "validate_points": "faces",
}

if TYPE_CHECKING:
    from prismcore.geometry.calibration import Calibration, calibrate, calibrate_images, find_board
    from prismcore.geometry.edges import EdgeFit, refine_quad
    from prismcore.geometry.faces import FaceQuads, clicked_quads, validate_points
    from prismcore.geometry.perspective import BoxFit, fit_box, fit_rectangle
    from prismcore.geometry.rounding import RadiusEstimate, estimate_edge_radius

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

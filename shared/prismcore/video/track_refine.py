"""The engine's own refinement of tracked points (`prismcore.video.tracking.track_points`'s
`refine`): the seven points run through the scan's plan as clicks on a photo do, and come back
as the fitted box's corners."""

from __future__ import annotations

from typing import Any

import numpy as np

from prismcore.errors import InputError
from prismcore.geometry.faces import clicked_quads, quad_labels
from prismcore.video.tracking import POINT_NAMES, Refiner, to_reference

__all__ = ["box_refiner"]


def box_refiner(spec_fields: dict[str, Any] | None = None) -> Refiner:
    """The engine's refinement of clicked points as a tracker's `refine`.

    The points run through `plan_scan` as clicks on a photo do (edges fitted to sub-pixel lines,
    the box fitted to them, the snap and fit guards); the refined points are the fitted box's
    corners. `spec_fields` adds to the photo spec (side_face, focal_px, camera, scale...).

    Returns
    -------
    callable
        (image (H, W, 3) RGB, points (7, 2)) -> points (7, 2); InputError when the plan refuses.
    """
    from prismcore.scan.pipeline import plan_scan
    from prismcore.spec import ScanSpec

    extra = dict(spec_fields or {})

    def refine(image: np.ndarray, points: np.ndarray) -> np.ndarray:
        spec = ScanSpec.model_validate({"image": "frame", "formats": ["csv"], **extra,
                                        "points": to_reference(points).model_dump()})
        plan = plan_scan(spec, image)
        side_face = plan.side_face
        front, side = plan.faces[0].region, plan.faces[1].region
        labels = quad_labels(clicked_quads(to_reference(points), two_photo=False, side_face=side_face))
        out = points.copy()
        for quad, names in ((front, labels[0]), (side, labels[1])):
            for corner, name in zip(quad, names, strict=True):
                if name is not None:
                    out[POINT_NAMES.index(name)] = corner
        # P4 is the front's corner it marks (P2, or P1), as the box has one corner there.
        out[3] = out[1] if side_face == "right" else out[0]
        if not np.isfinite(out).all():
            raise InputError("the refined box has no finite corners")
        return out

    return refine

"""What a calibrated station can measure, before any part is put on it.

Over the support (the board's area as calibrated): millimetres per pixel at its near edge (the one
closest to the camera, the finest) and its far edge (the coarsest), and from them, where the
scale is coarsest:

* the smallest part: a side spanning ``measure._SMALL_SPAN_PX`` px (under it, and with its sigma
  over 2 % of it, a measurement warns that the part is too small in the photo);
* the smallest tolerance: the +-T for which the station's stated one sigma there, the outline
  placed to ``measure._SYSTEMATIC_PX`` px along a whole side and 0.2 % of the side, takes 30 % of
  the tolerance by AIAG MSA's formula (%GRR = 6 sigma / 2T <= 30 %, so T >= 10 sigma). A
  verification (``verify``) measures the real repeatability, usually smaller.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from prismcore.station.calibrate import Station
from prismcore.station.certify import mm_per_px, plane_homography
from prismcore.station.measure import _SMALL_SPAN_PX, _SYSTEMATIC_PX
from prismcore.station.verify import MAX_GRR_PERCENT

__all__ = ["capability", "capability_lines"]

_RELATIVE_SIGMA = 0.002  # measure's share of a side in its sigma


def capability(station: Station) -> dict[str, Any]:
    """The station's scale over its support and what it can hold there.

    Returns
    -------
    dict
        ``mm_per_px`` {near, far} (the board's edges nearest and farthest from the camera, each at
        its middle), ``min_part_mm`` and ``min_tolerance_mm`` (+-T) at the far edge, and
        ``min_tolerance_near_mm`` at the near edge, with ``rule`` in words.
    """
    # a degenerate station.json (a pose or camera whose figures overflow) gives inf or nan here,
    # not a warning: the API refuses a summary that is not finite
    with np.errstate(all="ignore"):
        K = station.camera.matrix()
        H = plane_homography(K, station.plane)
        bw, bh = station.board.size_mm
        edges = np.array([[bw / 2, 0.0], [bw, bh / 2], [bw / 2, bh], [0.0, bh / 2]])
        camera = station.plane.camera_centre()[:2]
        order = np.argsort(np.linalg.norm(edges - camera, axis=1))
        scales = mm_per_px(H, edges[[order[0], order[-1]]])
    near, far = float(scales[0]), float(scales[1])
    min_part = _SMALL_SPAN_PX * far

    def tolerance(scale: float) -> float:
        with np.errstate(all="ignore"):  # a degenerate pose's inf stays inf (the caller checks)
            sigma = float(np.hypot(_SYSTEMATIC_PX * scale, _RELATIVE_SIGMA * min_part))
        return 6.0 * sigma / (2.0 * MAX_GRR_PERCENT / 100.0)

    return {
        "mm_per_px": {"near": round(near, 4), "far": round(far, 4)},
        "min_part_mm": round(min_part, 1),
        "min_tolerance_mm": round(tolerance(far), 2),
        "min_tolerance_near_mm": round(tolerance(near), 2),
        "rule": (f"smallest part: a side of {_SMALL_SPAN_PX:g} px at the far edge; smallest tolerance +-T: "
                 f"%GRR = 6 sigma / 2T at most {MAX_GRR_PERCENT:g} % with the stated sigma there "
                 f"({_SYSTEMATIC_PX:g} px of outline along a side, and 0.2 % of it)"),
    }


def capability_lines(station: Station) -> list[str]:
    """The capability in words, as `prism station calibrate` and `prism station show` print it."""
    c = capability(station)
    s = c["mm_per_px"]
    return [
        f"scale: {s['near']:.3f} mm/px at the support's near edge, {s['far']:.3f} mm/px at its far edge",
        f"capability: parts from {c['min_part_mm']:.0f} mm, tolerances from +-{c['min_tolerance_mm']:.2f} mm "
        f"(+-{c['min_tolerance_near_mm']:.2f} mm at the near edge); a smaller part needs the camera closer",
    ]

"""Station mode: a camera calibrated to the support a part stands on, so a box resting on it is
measured from its silhouette in millimetres, with no click and no known edge.

``board`` describes, draws and finds calibration boards; ``calibrate`` makes a station (camera,
support plane, plate); ``segment`` re-registers a photo on the plate and outlines the part;
``boxfit`` fits the box to the outline; ``measure`` chains them and derives the seven points;
``verify`` holds the statistics of a verification with a reference part; ``certify`` what a
measurement states of its station (the verification's status, the camera's drift since
calibration and its cost); ``capability`` the scale over the support and the smallest part and
tolerance it holds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "BoardSpec",
    "Station",
    "StationMeasurement",
    "Verification",
    "board_image",
    "calibrate_station",
    "default_board",
    "find_board_corners",
    "measure_on_station",
    "verify_placements",
]

# Imported on first use (`prismcore._lazy`), like the other subpackages: `prism board` or the
# API reading a station.json loads neither the part's segmentation nor the box fit (scipy).
_EXPORTS = {
    "BoardSpec": "board",
    "Station": "calibrate",
    "StationMeasurement": "measure",
    "board_image": "board",
    "calibrate_station": "calibrate",
    "default_board": "board",
    "find_board_corners": "board",
    "measure_on_station": "measure",
    "Verification": "verify",
    "verify_placements": "verify",
}

if TYPE_CHECKING:
    from prismcore.station.board import BoardSpec, board_image, default_board, find_board_corners
    from prismcore.station.calibrate import Station, calibrate_station
    from prismcore.station.measure import StationMeasurement, measure_on_station
    from prismcore.station.verify import Verification, verify_placements

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

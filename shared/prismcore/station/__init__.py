"""Station mode: a camera calibrated to the support a part stands on, so a box resting on it is
measured from its silhouette in millimetres, with no click and no known edge.

``board`` describes, draws and finds calibration boards; ``calibrate`` makes a station (camera,
support plane, plate); ``segment`` re-registers a photo on the plate and outlines the part;
``boxfit`` fits the box to the outline; ``measure`` chains them and derives the seven points.
"""

from __future__ import annotations

from prismcore.station.board import BoardSpec, board_image, default_board, find_board_corners
from prismcore.station.calibrate import Station, calibrate_station
from prismcore.station.measure import StationMeasurement, measure_on_station

__all__ = [
    "BoardSpec",
    "Station",
    "StationMeasurement",
    "board_image",
    "calibrate_station",
    "default_board",
    "find_board_corners",
    "measure_on_station",
]

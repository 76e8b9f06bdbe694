"""Re-registration on a station: a camera that did not move keeps the calibration's pose and
pixels ("unmoved"); one turned by 1-3 px since the plate is registered again and its shift said
(prismsynth's truth: `StationScene.nudge_px`)."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.station.registration import register
from prismcore.station.undistort import undistorter

from .conftest import scene, station_for


def _registered(sc, station):
    """The scene's photo registered on the station as `measure_on_station` does (undistorted)."""
    und = undistorter(station.camera)
    plate = station.plate()
    assert plate is not None
    return register(und.image(sc.photo), und.image(plate), sc.photo, station.board, station.camera,
                    station.plane)


@pytest.mark.parametrize("seed", [10, 12, 14, 16])
def test_a_camera_that_did_not_move_keeps_its_calibration(seed):
    sc = scene(seed, nudge=False)
    station = station_for(sc)
    reg = _registered(sc, station)
    assert reg.source == "unmoved"
    assert reg.shift_px < 0.25 and np.array_equal(reg.homography, np.eye(3))
    assert reg.pose == station.plane


@pytest.mark.parametrize("seed", [11, 13, 15, 17])
def test_a_camera_turned_since_calibration_is_registered_again(seed):
    sc = scene(seed, nudge=True)
    assert sc.nudge_px >= 1.0
    station = station_for(sc)
    reg = _registered(sc, station)
    assert reg.source in ("board", "plate")
    # the shift measured is the turn the scene was given (at the image centre), to half a pixel
    assert reg.shift_px == pytest.approx(sc.nudge_px, abs=0.5)

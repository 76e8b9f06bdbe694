"""Station tests: scenes rendered by prismsynth.station, stations calibrated from them."""

from __future__ import annotations

from functools import cache

import pytest

from prismcore.camera import CameraModel
from prismcore.station import Station, calibrate_station
from prismsynth.station import StationScene, station_scene


def true_camera(scene: StationScene) -> CameraModel:
    su = scene.setup
    w, h = su.image_size
    return CameraModel(fx=su.K[0, 0], fy=su.K[1, 1], cx=su.K[0, 2], cy=su.K[1, 2],
                       dist=[float(v) for v in su.dist], image_width=w, image_height=h)


@cache
def scene(seed: int, **kwargs: object) -> StationScene:
    return station_scene(seed, **kwargs)  # type: ignore[arg-type]


def station_for(sc: StationScene) -> Station:
    """The station as calibrated before the part came: the camera known, the plate as the plane photo."""
    return calibrate_station(sc.setup.board, sc.plate, camera=true_camera(sc), plate=sc.plate)


@pytest.fixture
def make_station():
    return station_for

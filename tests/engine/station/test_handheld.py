"""Hand-held, no station: the board around the part gives the plane, the scale and the focal
length; the part is found against the board's own pattern."""

from __future__ import annotations

import pytest

from prismcore.errors import InputError
from prismcore.station.handheld import board_camera, measure_on_board
from prismsynth.station import StationScene, station_scene, station_setup

from .conftest import true_camera

# Seeds whose part lies within the board's area in the photo (others are refused: see below).
INSIDE = (2, 4, 9)


def _scene(seed: int) -> StationScene:
    return station_scene(5000 + seed, station_setup(5000 + seed), nudge=False, inside_board=True,
                         max_size_mm=80)


@pytest.mark.parametrize("seed", INSIDE)
@pytest.mark.parametrize("known_camera", [True, False])
def test_a_part_on_the_board_is_measured_from_the_board_alone(seed, known_camera) -> None:
    sc = _scene(seed)
    m = measure_on_board(sc.photo, sc.setup.board, true_camera(sc) if known_camera else None)
    assert sc.box is not None
    for key, true in sc.box.dimensions.items():
        assert abs(m.dimensions[key] - true) <= max(0.015 * true, 1.0), (key, m.dimensions, true)
        assert abs(m.dimensions[key] - true) <= 3 * m.uncertainty[key] + 0.3
    if not known_camera:
        assert any("found from the board" in w for w in m.warnings)


@pytest.mark.parametrize("seed", INSIDE)
def test_the_focal_length_found_from_the_board_is_within_1_percent(seed) -> None:
    sc = _scene(seed)
    assert abs(board_camera(sc.photo, sc.setup.board).fx / sc.setup.K[0, 0] - 1) < 0.01


def test_a_part_whose_outline_reaches_past_the_board_is_refused_naming_it() -> None:
    sc = _scene(0)
    with pytest.raises(InputError, match="reaches past the board"):
        measure_on_board(sc.photo, sc.setup.board, true_camera(sc))


def test_a_photo_without_the_board_is_refused() -> None:
    sc = _scene(2)
    with pytest.raises(InputError, match="board corners found"):
        measure_on_board(sc.plate[:200, :300].copy(), sc.setup.board)

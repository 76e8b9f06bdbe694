"""A part on a station, measured with no click and no known edge, over many rendered scenes:
bounds with a margin, not one seed's outcome. benchmarks/station.py prints the full figures."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.errors import InputError
from prismcore.station import measure_on_station
from prismsynth.station import station_scene, station_setup

from .conftest import scene, station_for

SEEDS = range(12)


def _errors(seed: int) -> tuple[bool, list[tuple[float, float, float, bool]]]:
    sc = scene(seed)
    try:
        m = measure_on_station(sc.photo, station_for(sc))
    except InputError:
        return False, []
    assert sc.box is not None
    true = sc.box.dimensions
    return True, [(m.dimensions[k] - true[k], true[k], m.uncertainty[k], bool(m.warnings)) for k in true]


@pytest.fixture(scope="module")
def outcomes() -> dict[int, tuple[bool, list]]:
    return {seed: _errors(seed) for seed in SEEDS}


def test_most_parts_are_found_and_measured_within_1_percent_or_1_mm(outcomes) -> None:
    found = [s for s, (ok, _) in outcomes.items() if ok]
    assert len(found) >= 9, f"found {len(found)} of {len(outcomes)}"
    dims = [d for s in found for d in outcomes[s][1]]
    within = [abs(err) <= max(0.01 * true, 1.0) for err, true, _, _ in dims]
    assert np.mean(within) >= 0.8, f"{np.mean(within):.0%} of {len(dims)} dimensions within max(1 %, 1 mm)"


def test_no_dimension_is_off_by_more_than_5_percent_without_a_warning(outcomes) -> None:
    silent = [(s, err / true) for s, (ok, dims) in outcomes.items() if ok
              for err, true, _, warned in dims if abs(err) > 0.05 * true and not warned]
    assert not silent


def test_width_is_the_longer_footprint_side_and_the_sigma_is_positive() -> None:
    sc = scene(4)
    m = measure_on_station(sc.photo, station_for(sc))
    assert m.dimensions["width"] >= m.dimensions["depth"]
    assert all(0 < v < 5 for v in m.uncertainty.values())
    assert m.points.shape == (7, 2) and m.side_face in ("right", "left", "top")


def test_an_empty_support_is_refused_as_no_part_found() -> None:
    sc = station_scene(40, parts=0)
    with pytest.raises(InputError, match="no part found"):
        measure_on_station(sc.photo, station_for(sc))


def test_two_parts_are_refused_one_part_per_photo() -> None:
    setup = station_setup(41, distance_mm=1100)
    sc = station_scene(41, setup, parts=2, max_size_mm=90)
    with pytest.raises(InputError, match="2 parts found: one part per photo"):
        measure_on_station(sc.photo, station_for(sc))


@pytest.fixture(scope="module")
def setup_3():
    setup = station_setup(3, image_size=(1280, 1024))
    return setup, station_for(station_scene(100, setup))


@pytest.mark.parametrize("seed", [200, 202, 207, 208])
def test_a_small_second_part_beside_a_large_one_is_refused_not_left_out(setup_3, seed) -> None:
    # Each second part is a cube of 20-22 mm beside one of 60-170 mm: under a fifth of its area in
    # the photo, and next to it (207) or apart. It was once left out unsaid, the large one measured.
    setup, station = setup_3
    sc = station_scene(seed, setup, parts=2)
    assert min(b.length_mm for b in sc.extra_boxes) <= 25
    with pytest.raises(InputError, match=r"2 parts found: one part per photo \(one of them about"):
        measure_on_station(sc.photo, station)


def test_a_camera_moved_far_since_calibration_is_refused() -> None:
    sc = scene(4)
    other = station_scene(4, station_setup(5))  # another camera position over another table
    with pytest.raises(InputError, match="camera"):
        measure_on_station(sc.photo, station_for(other).model_copy(update={"camera": station_for(sc).camera}))


def test_a_part_cut_by_the_photos_edge_is_refused() -> None:
    sc = scene(4)
    photo = sc.plate.copy()
    # the part's corner of the photo laid at the photo's left edge: the outline leaves the frame
    photo[300:700, :260] = sc.photo[300:700, 520:780]
    with pytest.raises(InputError, match="cut by the photo's edge"):
        measure_on_station(photo, station_for(sc))


def test_a_part_that_is_not_a_box_is_refused_naming_its_outline() -> None:
    import cv2

    sc = scene(4)
    photo = sc.plate.copy()
    triangle = np.array([[520, 420], [760, 470], [600, 690]], np.int32)
    cv2.fillPoly(photo, [triangle], (200, 40, 40))  # a flat triangle of red: no box has that outline
    with pytest.raises(InputError, match=r"not a box resting flat|degenerate"):
        measure_on_station(photo, station_for(sc))


def test_a_part_close_to_the_supports_colour_is_flagged_with_the_contrast() -> None:
    sc = station_scene(7, near_table_colour=True)
    try:
        m = measure_on_station(sc.photo, station_for(sc))
    except InputError:
        return  # refused, with the reason: also not a silent number
    assert any("contrast" in w or "barely differs" in w or "pieces" in w for w in m.warnings) or all(
        abs(m.dimensions[k] - v) <= max(0.01 * v, 1.0) for k, v in sc.box.dimensions.items())


@pytest.fixture(scope="module")
def small_in_the_photo() -> list[tuple[int, dict[str, float], dict[str, float], dict[str, float], list[str]]]:
    """Parts of 20-40 mm in 640x512 photos (the service's batch test's size): a side spans 15-40 px."""
    setup = station_setup(41, image_size=(640, 512))
    station = station_for(station_scene(100, setup))
    measured = []
    for seed in range(1000, 1012):
        sc = station_scene(seed, setup, max_size_mm=40)
        try:
            m = measure_on_station(sc.photo, station)
        except InputError:
            continue
        assert sc.box is not None
        measured.append((seed, sc.box.dimensions, m.dimensions, m.uncertainty, m.warnings))
    return measured


def test_a_part_small_in_the_photo_says_its_dimensions_are_uncertain(small_in_the_photo) -> None:
    """The oracle is the render's truth: a dimension off by over 5 % is warned; and a dimension whose
    1 sigma is over 2 % of it is named in a warning (one at 640x512 read 6 % long, unsaid)."""
    assert len(small_in_the_photo) >= 8
    for seed, true, dims, sigma, warnings in small_in_the_photo:
        for k in true:
            if abs(dims[k] - true[k]) > 0.05 * true[k]:
                assert warnings, (seed, k, true[k], dims[k])
            if sigma[k] > 0.02 * dims[k]:
                assert any(f"{k} {dims[k]:.1f} +- " in w or w.startswith(f"{k} is poorly determined")
                           for w in warnings), (seed, k, warnings)
    assert any("uncertain by over 2%: the part spans" in w for *_, warnings in small_in_the_photo
               for w in warnings)

"""Hand-held, no station: the board around the part gives the plane, the scale and the focal
length; the part is found against the board's own pattern and, where it rises past the board in
the photo, against the table round it read from the photo itself."""

from __future__ import annotations

import dataclasses
from functools import cache

import cv2
import numpy as np
import pytest

from prismcore.errors import InputError
from prismcore.station import background, handheld
from prismcore.station.handheld import board_camera, measure_on_board
from prismsynth.station import StationScene, station_scene, station_setup

from .conftest import true_camera

# Seeds measured with the camera known as well; seed 0's part (66 mm tall, seen from 32 degrees
# up) rises past the board's far edge in the photo.
KNOWN = (0, 2, 9)
MANY = range(20)


@cache
def _scene(seed: int) -> StationScene:
    return station_scene(5000 + seed, station_setup(5000 + seed), nudge=False, inside_board=True,
                         max_size_mm=80)


def _off_unwarned(m, true: dict[str, float]) -> list[str]:
    warned = [w for w in m.warnings if "found from the board" not in w]
    return [k for k, v in true.items() if abs(m.dimensions[k] - v) > 0.05 * v and not warned]


def test_hand_held_photos_meet_the_station_targets_with_a_margin() -> None:
    """Over 20 renders (the benchmark's first 20, seed 18's part beside its shadow's edge where
    the board's light is smoothed across it; its 40 and those of --seed 1 give the figures):
    found >= 90 %, within max(1 %, 1 mm) >= 90 %, within 3 sigma >= 95 %, none over 5 % off
    without a warning."""
    found, within, in3, total, silent = 0, 0, 0, 0, []
    for seed in MANY:
        sc = _scene(seed)
        assert sc.box is not None
        try:
            m = measure_on_board(sc.photo, sc.setup.board)
        except InputError:
            continue
        found += 1
        for key, true in sc.box.dimensions.items():
            err = abs(m.dimensions[key] - true)
            total += 1
            within += err <= max(0.01 * true, 1.0)
            in3 += err <= 3 * m.uncertainty[key]
        silent += _off_unwarned(m, sc.box.dimensions)
    assert found >= 0.9 * len(MANY), found
    assert within >= 0.9 * total, (within, total)
    assert in3 >= 0.95 * total, (in3, total)
    assert not silent


@pytest.mark.parametrize("seed", KNOWN)
def test_a_part_on_the_board_is_measured_with_the_camera_known(seed) -> None:
    sc = _scene(seed)
    m = measure_on_board(sc.photo, sc.setup.board, true_camera(sc))
    assert sc.box is not None
    for key, true in sc.box.dimensions.items():
        assert abs(m.dimensions[key] - true) <= max(0.015 * true, 1.0), (key, m.dimensions, true)
        assert abs(m.dimensions[key] - true) <= 3 * m.uncertainty[key] + 0.3
    assert not any("found from the board" in w for w in m.warnings)


@pytest.mark.parametrize("seed", (2, 4, 9))
def test_the_focal_length_found_from_the_board_is_within_1_percent(seed) -> None:
    sc = _scene(seed)
    assert abs(board_camera(sc.photo, sc.setup.board).fx / sc.setup.K[0, 0] - 1) < 0.01


@cache
def _lens_scene(k1: float) -> StationScene:
    setup = station_setup(5002)
    setup = dataclasses.replace(setup, dist=np.array([k1, 0.0, 0.0, 0.0, 0.0]))
    return station_scene(5002, setup, nudge=False, inside_board=True, max_size_mm=80)


def test_a_lens_s_distortion_is_found_from_the_board_and_the_part_measured() -> None:
    """k1 -0.15 (with the focal length fixed at 0 its corners missed a pose by about 1 px): k1
    found within 0.03, the focal length within 1 %, the part within max(2 %, 1.5 mm)."""
    sc = _lens_scene(-0.15)
    cam = board_camera(sc.photo, sc.setup.board)
    assert abs(cam.dist[0] + 0.15) < 0.03, cam.dist
    assert abs(cam.fx / sc.setup.K[0, 0] - 1) < 0.01
    m = measure_on_board(sc.photo, sc.setup.board)
    assert sc.box is not None
    for key, true in sc.box.dimensions.items():
        assert abs(m.dimensions[key] - true) <= max(0.02 * true, 1.5), (key, m.dimensions, true)
    assert any("k1 -0.1" in w for w in m.warnings), m.warnings


def test_a_distortion_beyond_what_one_view_can_be_trusted_for_is_refused_naming_it(monkeypatch) -> None:
    monkeypatch.setattr(handheld, "_MAX_K1", 0.05)
    sc = _lens_scene(-0.15)
    with pytest.raises(InputError, match=r"distortion found from the board .* needs --camera"):
        measure_on_board(sc.photo, sc.setup.board)


def test_a_part_reaching_past_what_is_modelled_is_refused_naming_it(monkeypatch) -> None:
    """With no table modelled round the board (as before the table's model), seed 0's part rises
    past what is known: refused, saying so."""
    monkeypatch.setattr(background, "TABLE_HEIGHT", 0.0)
    sc = _scene(0)
    with pytest.raises(InputError, match="reaches past the board"):
        measure_on_board(sc.photo, sc.setup.board, true_camera(sc))


def test_a_part_cut_by_the_photo_s_edge_is_refused() -> None:
    sc = _scene(0)
    assert sc.box is not None
    su = sc.setup
    rows = cv2.projectPoints(sc.box.corners(), cv2.Rodrigues(su.R)[0], su.t, su.K, su.dist)[0][:, 0, 1]
    top = int((rows.min() + rows.max()) / 2)  # the photo cut across the part
    with pytest.raises(InputError, match="cut by the photo's edge"):
        measure_on_board(sc.photo[top:].copy(), sc.setup.board)


def test_a_photo_without_the_board_is_refused() -> None:
    sc = _scene(2)
    with pytest.raises(InputError, match="board corners found"):
        measure_on_board(sc.plate[:200, :300].copy(), sc.setup.board)


def test_the_board_lit_beside_a_shadow_s_edge_is_not_taken_for_a_second_part() -> None:
    """Seed 18: a marker lit beside the part's shadow, the board's light smoothed across the
    shadow's edge darker than it, was refused as a second part 21 mm across; it is the board."""
    sc = _scene(18)
    assert sc.box is not None
    m = measure_on_board(sc.photo, sc.setup.board)
    assert not any("speck" in w for w in m.warnings), m.warnings
    for key, true in sc.box.dimensions.items():
        assert abs(m.dimensions[key] - true) <= max(0.015 * true, 1.0), (key, m.dimensions, true)


@pytest.mark.parametrize("shift_px", [3.0, 6.0, 12.0])
def test_a_board_corner_refined_off_its_place_is_left_out_and_the_rest_kept(shift_px) -> None:
    """A corner pulled onto a part's edge beside it (here moved by `shift_px`) is left out of the
    one-view fit; the view found in the photo, whose corners all agree, is kept whole."""
    sc = _scene(2)
    view = handheld._board_view(sc.photo, sc.setup.board)
    size = (sc.photo.shape[1], sc.photo.shape[0])
    assert handheld.without_strays(view, size) is view
    moved = view.image_points.copy()
    moved[len(view) // 2] += shift_px / np.sqrt(2)
    strayed = dataclasses.replace(view, image_points=moved)
    kept = handheld.without_strays(strayed, size)
    assert sorted(set(view.ids) - set(kept.ids)) == [view.ids[len(view) // 2]]
    assert board_camera(sc.photo, sc.setup.board, kept).rms_px < 0.5


def test_a_view_whose_corners_all_miss_alike_is_kept_whole() -> None:
    """Noise on every corner is no stray: nothing is left out (the RMS check judges the view)."""
    sc = _scene(2)
    view = handheld._board_view(sc.photo, sc.setup.board)
    noisy = view.image_points + np.random.default_rng(3).normal(0, 1.0, view.image_points.shape)
    noisy_view = dataclasses.replace(view, image_points=noisy)
    assert len(handheld.without_strays(noisy_view, (sc.photo.shape[1], sc.photo.shape[0]))) >= len(view) - 1


@pytest.mark.parametrize("seed", [2, 4, 9])
def test_a_thing_beside_the_board_s_squares_is_left_out_not_a_second_part(seed) -> None:
    """A red strip (a pen, a cable) on the table a square and more past the board's far edge, where a
    part rising past the board is looked for and within the reach once allowed to a part: it
    touches no square, so it is left out and said, and the part is measured as without it."""
    sc = _scene(seed)
    su = sc.setup
    assert sc.box is not None
    bw, bh = su.board.size_mm
    sq = su.board.square_mm
    centre = -su.R.T @ np.ravel(su.t)  # the camera in the board's frame: the far edge is away from it
    y0, y1 = (-1.8 * sq, -1.1 * sq) if centre[1] > bh / 2 else (bh + 1.1 * sq, bh + 1.8 * sq)
    strip = np.array([[0.3 * bw, y0, 0], [0.6 * bw, y0, 0], [0.6 * bw, y1, 0], [0.3 * bw, y1, 0]])
    px = cv2.projectPoints(strip, cv2.Rodrigues(su.R)[0], su.t, su.K, su.dist)[0].reshape(-1, 2)
    h, w = sc.photo.shape[:2]
    assert ((px >= 0) & (px < (w, h))).all()
    photo = sc.photo.copy()
    cv2.fillConvexPoly(photo, np.round(px).astype(np.int32), (200, 30, 30), lineType=cv2.LINE_AA)
    m = measure_on_board(photo, su.board, true_camera(sc))
    assert any("apart from the board left out" in w for w in m.warnings), m.warnings
    for key, true in sc.box.dimensions.items():
        assert abs(m.dimensions[key] - true) <= max(0.015 * true, 1.0), (key, m.dimensions, true)

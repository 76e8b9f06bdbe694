"""The shadow told from a dark part on the board: a shadow scales the board's white and black alike
and keeps its pattern, a dark part hides it. Checked on drawn patterns against the scale each
pixel was drawn with."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from prismcore.station.background import shadow_difference, with_table
from prismcore.station.board import board_image
from prismcore.station.handheld import _hue, expected_board, shadow_floor
from prismcore.station.segment import SHADOW_RANGE
from prismsynth.station import station_board

SQUARE = 40  # px


def _board() -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's ChArUco board drawn at 1 px a mm (40 px squares, 240 x 360 px) as printed
    (white 230, black 38, RGB uint8), and its pattern (1 white, 0 black)."""
    pattern = (board_image(station_board(), 1.0) > 127).astype(np.float32)
    plate = np.where(pattern[..., None] > 0.5, 230.0, 38.0) * np.ones(3)
    return plate.astype(np.uint8), pattern


@pytest.mark.parametrize("depth", [0.45, 0.6, 0.7])
def test_a_shadow_on_the_board_is_explained_by_its_scale(depth) -> None:
    """A shadow (the board scaled by 0.45-0.7 over a block of squares): no difference within it,
    its edge included; the floor there (2 px in from its edge: the floor is found at a third of
    the size) no higher than the shadow's scale."""
    plate, pattern = _board()
    photo = plate.astype(np.float32)
    shade = np.zeros(pattern.shape, bool)
    shade[60:200, 70:230] = True
    photo[shade] *= depth
    floor = shadow_floor(photo.astype(np.uint8), plate, pattern, SQUARE)
    inside = np.zeros_like(shade)
    inside[62:198, 72:228] = True
    assert np.all(floor[inside] <= depth + 0.02), floor[inside].max()
    diff = shadow_difference(photo.round(), plate.astype(np.float32), (floor, SHADOW_RANGE[1]))
    assert np.percentile(diff[shade], 99) < 4.0, np.percentile(diff[shade], 99)


@pytest.mark.parametrize("grey", [40, 48, 55])
def test_a_dark_grey_part_over_the_white_squares_is_not_taken_for_a_shadow(grey) -> None:
    """A uniform dark grey patch (40-55 levels: the black print's or a little brighter, a fifth to
    a quarter of the white, as a deep shadow darkens it) over squares of both prints: as a
    shadow's scale alone allows, the white under it barely differs; with the black squares' scale
    as the floor it differs by most of the white."""
    plate, pattern = _board()
    photo = plate.copy()
    part = np.zeros(pattern.shape, bool)
    part[80:160, 100:220] = True
    photo[part] = grey
    white_under = part & (pattern > 0.5)
    plain = shadow_difference(photo, plate)
    held = shadow_difference(photo, plate, (shadow_floor(photo, plate, pattern, SQUARE), SHADOW_RANGE[1]))
    assert np.median(plain[white_under]) < 0.25 * 230  # a shadow's scale would take it
    assert np.median(held[white_under]) > (0.7 * 230 - grey) * 1.5, np.median(held[white_under])
    away = np.ones_like(part)
    away[60:180, 80:240] = False
    assert np.max(held[away]) < 1.0  # the board away from the part: no difference


def test_the_table_s_fallbacks_say_so() -> None:
    plate, _ = _board()
    cover = np.zeros(plate.shape[:2], np.float32)
    _, known, notes = with_table(plate, plate, cover, np.array([[0, 0], [10, 0], [10, 10]], np.float64))
    assert not known.any()
    assert notes and "no table is modelled" in notes[0]
    notes = []
    level = np.full(plate.shape, 100.0, np.float32)
    weight = np.zeros(plate.shape[:2], np.float32)
    weight[:5, :5] = 1
    assert _hue(level, plate.astype(np.float32), weight, notes) is level
    assert notes and "25 pixels" in notes[0]


def test_the_table_is_modelled_in_its_zone_only() -> None:
    """Outside the zone and the board the plate is the photo, to the level."""
    rng = np.random.default_rng(3)
    photo = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
    board_plate = np.full_like(photo, 128)
    cover = np.zeros(photo.shape[:2], np.float32)
    cover[100:140, 100:160] = 1
    zone = np.array([[80, 60], [200, 60], [200, 150], [80, 150]], np.float64)
    plate, known, notes = with_table(photo, board_plate, cover, zone)
    assert not notes
    assert known[100:140, 100:160].all() and known[70, 150] and not known[20, 20] and not known[200, 300]
    np.testing.assert_array_equal(plate[~known], photo[~known])
    np.testing.assert_array_equal(plate[110:130, 110:150], board_plate[110:130, 110:150])


@pytest.mark.parametrize("part", [24, 36, 48])
def test_a_part_rising_past_the_board_differs_from_the_table_modelled_there(part) -> None:
    """A part `part` px across over a board's edge, rising past it over a wood-like table (grain
    +-12 levels): the table's texture is read from the table alone, so the part's half over the
    table differs from the plate by most of its contrast (the board's own difference from the
    table, in the median's window, had let it through as grain), and the grain by little."""
    rng = np.random.default_rng(5)
    h, w = 480, 640
    grain = rng.normal(0, 6, (h, 1, 1)) + rng.normal(0, 4, (h, w, 1))
    table = np.clip(np.array([150.0, 110.0, 70.0]) + grain, 0, 255)
    cover = np.zeros((h, w), np.float32)
    cover[300:420, 200:440] = 1  # the board
    photo = table.copy()
    photo[cover > 0] = 200.0  # the board's white
    y0, x0 = 300 - part // 2, 320 - part // 2
    photo[y0:y0 + part, x0:x0 + part] = (60.0, 90.0, 200.0)  # a blue part rising past the board
    photo = photo.astype(np.uint8)
    zone = np.array([[100, 40], [540, 40], [540, 460], [100, 460]], np.float64)
    plate, known, _ = with_table(photo, np.full_like(photo, 200), cover, zone)
    assert known[y0:y0 + part, x0:x0 + part].all()
    inner = (slice(y0 + 2, 300 - 2), slice(x0 + 2, x0 + part - 2))  # over the table
    diff = np.linalg.norm(photo[inner].astype(float) - plate[inner].astype(float), axis=-1)
    contrast = float(np.linalg.norm(np.array([60.0, 90.0, 200.0]) - [150.0, 110.0, 70.0]))
    assert np.median(diff) > 0.7 * contrast, (np.median(diff), contrast)
    wood = (slice(60, 180), slice(120, 200))
    grain_diff = np.linalg.norm(photo[wood].astype(float) - plate[wood].astype(float), axis=-1)
    assert np.median(grain_diff) < 6, np.median(grain_diff)


def test_the_board_is_modelled_lit_beside_a_shadow_s_edge() -> None:
    """The board's light is smoothed over most of a square: a shadow's edge within that reach
    darkened the plate on its lit side (a lit marker beside a shadow then differed, 1.2-1.5 times
    its plate, read as a second part). The board half in a shadow (0.5): on the lit side up to
    its edge the plate is the photo's light within a fifth from 6 px off the edge and within
    SHADOW_RANGE's most from 20 px (before: 1.65 and 1.3 times); in the shadow, the photo is
    within SHADOW_RANGE's least."""
    board = station_board()
    pose_h = np.array([[1.0, 0, 20], [0, 1.0, 20], [0, 0, 1]])  # board mm -> photo px
    # the board drawn as the model draws it: its pattern at 3 px a mm, warped onto the photo
    to_photo = pose_h @ np.array([[1 / 3, 0, 0.5 / 3], [0, 1 / 3, 0.5 / 3], [0, 0, 1]])
    art = board_image(board, 3.0).astype(np.float32) / 255.0
    printed = cv2.GaussianBlur(cv2.warpPerspective(art, to_photo, (400, 280)), (0, 0), 0.7)
    inside = cv2.warpPerspective(np.ones_like(art), to_photo, (400, 280), flags=cv2.INTER_NEAREST) > 0.5
    photo = np.where(inside, 38.0 + 192.0 * printed, 120.0)[..., None] * np.ones(3, np.float32)
    photo[:, :200] *= 0.5  # board x < 180 mm in the shadow
    photo = photo.round().astype(np.uint8)
    plate, region = expected_board(photo, board, None, pose_h)  # type: ignore[arg-type]
    P, B = photo.astype(np.float32), plate.astype(np.float32)
    scale = (P * B).sum(axis=2) / ((B * B).sum(axis=2) + 1.0)
    white = B.mean(axis=2) > 100
    inner = cv2.erode(region.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool) & white
    near, far, shade = (inner.copy() for _ in range(3))
    near[:, :206] = False  # from 6 px off the shadow's edge (the smoothing spread it 1.5-1.7 times)
    far[:, :220] = False
    shade[:, 199:] = False
    assert np.percentile(scale[near], 99) <= 1.2, np.percentile(scale[near], 99)
    assert np.percentile(scale[far], 99) <= SHADOW_RANGE[1] + 0.03, np.percentile(scale[far], 99)
    assert np.percentile(scale[shade], 1) >= SHADOW_RANGE[0]

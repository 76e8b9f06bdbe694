"""Boards: board.json's fields, the picture's exact size, and its corners found where they are."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from prismcore.errors import InputError
from prismcore.station.board import BoardSpec, board_image, default_board, find_board_corners


@pytest.mark.parametrize(("paper", "squares"), [("A4", (7, 5)), ("A3", (9, 6)), ("letter", (5, 4))])
def test_the_default_board_fits_its_paper_with_whole_mm_squares(paper, squares) -> None:
    board = default_board(paper, squares)
    w, h = board.size_mm
    long, short = {"A4": (297, 210), "A3": (420, 297), "letter": (279.4, 215.9)}[paper]
    assert w <= long - 30 and h <= short - 30
    assert board.square_mm == int(board.square_mm) and board.marker_mm < board.square_mm


@pytest.mark.parametrize("px_per_mm", [2.0, 5.0, 10.0])
def test_the_png_is_the_boards_area_exactly_and_its_corners_are_found_at_their_mm(px_per_mm) -> None:
    board = default_board("A4", (7, 5))
    image = board_image(board, px_per_mm)
    w, h = board.size_mm
    assert image.shape == (round(h * px_per_mm), round(w * px_per_mm))
    # A white margin around it, as on paper: the corners' pixels are their mm times px_per_mm.
    pad = 40
    framed = np.pad(image, pad, constant_values=255)
    view = find_board_corners(framed, board)
    assert view is not None and len(view) == 6 * 4
    expected = view.object_points[:, :2] * px_per_mm - 0.5 + pad  # pixel centres at integers
    assert np.abs(view.image_points - expected).max() < 0.2


def test_a_chessboard_is_described_by_its_inner_corners() -> None:
    board = BoardSpec.model_validate({"type": "chessboard", "inner_corners": [9, 6], "square_mm": 25})
    assert (board.squares_x, board.squares_y) == (10, 7) and board.inner_corners == (9, 6)
    assert board.corner_points().shape == (54, 3)


@pytest.mark.parametrize(("fields", "says"), [
    ({"dictionary": "DICT_NOPE", "squares_x": 5, "squares_y": 4, "square_mm": 30, "marker_mm": 20},
     "dictionary"),
    ({"squares_x": 5, "squares_y": 4, "square_mm": 30, "marker_mm": 30}, "smaller"),
    ({"dictionary": "DICT_4X4_50", "squares_x": 20, "squares_y": 20, "square_mm": 10, "marker_mm": 7},
     "markers"),
])
def test_a_board_json_that_cannot_be_is_refused_naming_why(fields, says) -> None:
    with pytest.raises(ValidationError, match=says):
        BoardSpec.model_validate(fields)


def test_squares_too_small_for_the_paper_are_refused() -> None:
    with pytest.raises(InputError, match="under 5 mm"):
        default_board("A4", (32, 32))


@pytest.mark.parametrize("square_mm, marker_mm, px_per_mm", [(23.99, 17.99, 1.25), (55.89, 41.92, 18.5),
                                                             (39.0, 29.2, 3.3), (33.07, 24.8, 7.77)])
def test_a_board_of_measured_squares_is_drawn_at_any_scale(square_mm, marker_mm, px_per_mm) -> None:
    """OpenCV's drawing refuses some fractional sizes of a square (a marker rounded past the
    image): a board printed at another scale, its squares measured, is still drawn, at the size
    asked, its squares where the board says."""
    board = BoardSpec(type="charuco", dictionary="DICT_5X5_100", squares_x=9, squares_y=6,
                      square_mm=square_mm, marker_mm=marker_mm)
    img = board_image(board, px_per_mm)
    w, h = board.size_mm
    assert img.shape == (round(h * px_per_mm), round(w * px_per_mm))
    # the top-left square is black (OpenCV's pattern), its right neighbour white with a marker
    sq = square_mm * px_per_mm
    assert img[int(sq / 2), int(sq / 2)] < 60


def test_corners_beside_one_marker_are_found_when_a_part_hides_the_others() -> None:
    """Every other marker hidden (as a part over the board hides them): OpenCV's default wants two
    markers beside a corner and finds 6 corners here, under the 12 a plane needs; corners beside
    one marker are then taken, each where the board's own pattern puts it."""
    import cv2

    board = default_board("A4", (7, 5))
    px = 4.0
    img = cv2.copyMakeBorder(board_image(board, px), 40, 40, 40, 40, cv2.BORDER_CONSTANT, value=255)
    sq = board.square_mm * px
    white = [(r, c) for r in range(board.squares_y) for c in range(board.squares_x) if (r + c) % 2 == 1]
    for r, c in white[1::2]:
        y0, x0 = int(40 + (r + 0.1) * sq), int(40 + (c + 0.1) * sq)
        img[y0 : int(y0 + 0.8 * sq), x0 : int(x0 + 0.8 * sq)] = 150
    _, default_ids, _, _ = cv2.aruco.CharucoDetector(board.charuco()).detectBoard(img)
    assert default_ids is not None and len(default_ids) < 12
    view = find_board_corners(np.dstack([img] * 3), board, beside_one_marker=True)
    assert view is not None and len(view) >= 12
    expected = view.object_points[:, :2] * px + 40 - 0.5  # pixel centres: (i + 0.5) / px mm
    assert np.abs(view.image_points - expected).max() < 1.0

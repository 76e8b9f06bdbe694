"""Calibration boards: their description (board.json), their picture, and finding them in a photo.

A board is either OpenCV's ChArUco board (a chessboard whose white squares hold ArUco markers,
so a partly hidden board still names each corner it shows) or a plain chessboard (every inner
corner must show). Its frame is OpenCV's object-point frame: x along the board's width
(``squares_x`` squares), y along its height, z = 0 on the board, origin at the board's outer
top-left corner; z points into the support, so heights above the board are negative z.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, model_validator

from prismcore.errors import InputError

__all__ = ["PAPER_MM", "BoardSpec", "BoardView", "board_image", "default_board", "find_board_corners"]

# Paper sizes (portrait width, height), mm.
PAPER_MM: dict[str, tuple[float, float]] = {
    "A4": (210.0, 297.0),
    "A3": (297.0, 420.0),
    "letter": (215.9, 279.4),
}
_DICTIONARIES = {name: getattr(cv2.aruco, name) for name in dir(cv2.aruco) if name.startswith("DICT_")}
MIN_CORNERS = 6  # a pose from fewer corners of one plane is too weakly determined to use
_ENOUGH_CORNERS = 12  # found fewer with two markers beside each corner: corners beside one are tried


class BoardSpec(BaseModel):
    """What board.json says of a board: enough to find it and to know its corners in mm.

    ChArUco: ``squares_x`` x ``squares_y`` squares of ``square_mm``, markers of ``marker_mm``
    from ``dictionary``. Chessboard: ``squares_x`` x ``squares_y`` squares too (a board of
    9x6 inner corners has 10x7 squares); ``inner_corners`` is accepted as the alternative.
    """

    model_config = ConfigDict(extra="ignore", frozen=True)

    type: Literal["charuco", "chessboard"] = "charuco"
    dictionary: str = "DICT_5X5_100"
    squares_x: int = Field(ge=3, le=64)
    squares_y: int = Field(ge=3, le=64)
    square_mm: PositiveFloat
    marker_mm: PositiveFloat | None = None
    png_px_per_mm: PositiveFloat | None = None
    legacy_pattern: bool = False

    @model_validator(mode="before")
    @classmethod
    def _inner_corners(cls, data: object) -> object:
        if isinstance(data, dict) and "inner_corners" in data and "squares_x" not in data:
            corners = data["inner_corners"]
            if not (isinstance(corners, list | tuple) and len(corners) == 2):
                raise ValueError("inner_corners: expected [columns, rows]")
            data = {**data, "squares_x": int(corners[0]) + 1, "squares_y": int(corners[1]) + 1}
        return data

    @model_validator(mode="after")
    def _check(self) -> BoardSpec:
        if self.type == "charuco":
            if self.dictionary not in _DICTIONARIES:
                raise ValueError(
                    f"dictionary {self.dictionary!r}: not one of OpenCV's ArUco dictionaries "
                    "(e.g. DICT_5X5_100)"
                )
            if self.marker_mm is None or not self.marker_mm < self.square_mm:
                raise ValueError(
                    f"marker_mm {self.marker_mm}: a ChArUco board needs markers smaller "
                    f"than its squares ({self.square_mm} mm)"
                )
            markers = (self.squares_x * self.squares_y) // 2
            size = int(self.dictionary.rsplit("_", 1)[-1])
            if markers > size:
                raise ValueError(
                    f"a {self.squares_x}x{self.squares_y} ChArUco board needs {markers} "
                    f"markers; {self.dictionary} has {size}"
                )
        return self

    @property
    def size_mm(self) -> tuple[float, float]:
        """The board's (width, height), mm."""
        return self.squares_x * self.square_mm, self.squares_y * self.square_mm

    @property
    def inner_corners(self) -> tuple[int, int]:
        return self.squares_x - 1, self.squares_y - 1

    def corner_points(self) -> np.ndarray:
        """Every inner corner in the board's frame, (N, 3) float64 mm, in OpenCV's id order."""
        cols, rows = self.inner_corners
        grid = np.mgrid[1 : cols + 1, 1 : rows + 1].T.reshape(-1, 2) * self.square_mm
        return np.column_stack([grid, np.zeros(len(grid))])

    def charuco(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(_DICTIONARIES[self.dictionary])
        board = cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), float(self.square_mm), float(self.marker_mm or 0.0), dictionary
        )
        board.setLegacyPattern(self.legacy_pattern)
        return board

    def describe(self) -> dict[str, object]:
        """board.json's content."""
        out = self.model_dump(exclude_none=True)
        out["size_mm"] = list(self.size_mm)
        out["inner_corners"] = list(self.inner_corners)
        return out


def default_board(
    paper: str = "A4", squares: tuple[int, int] = (7, 5), *, margin_mm: float = 15.0, ruler_mm: float = 30.0
) -> BoardSpec:
    """The largest ChArUco board of `squares` that fits on `paper` (landscape) beside a margin and
    a strip for the check ruler and the board's parameters. Squares are whole millimetres."""
    if paper not in PAPER_MM:
        raise InputError(f"--paper {paper!r}: expected one of {', '.join(PAPER_MM)}")
    sx, sy = squares
    if not (3 <= sx <= 32 and 3 <= sy <= 32):
        raise InputError(f"--squares {sx}x{sy}: expected 3..32 squares each way")
    h, w = PAPER_MM[paper]  # landscape
    square = float(np.floor(min((w - 2 * margin_mm) / sx, (h - 2 * margin_mm - ruler_mm) / sy)))
    if square < 5:
        raise InputError(f"--squares {sx}x{sy} on {paper}: squares under 5 mm cannot be found")
    dictionary = next(
        name
        for name, size in (
            ("DICT_4X4_50", 50),
            ("DICT_5X5_100", 100),
            ("DICT_5X5_250", 250),
            ("DICT_5X5_1000", 1000),
        )
        if size >= sx * sy // 2
    )
    return BoardSpec(
        type="charuco",
        dictionary=dictionary,
        squares_x=sx,
        squares_y=sy,
        square_mm=square,
        marker_mm=round(square * 0.75, 1),
    )


def board_image(board: BoardSpec, px_per_mm: float) -> np.ndarray:
    """The board's area exactly, no margin: (H, W) uint8, H = squares_y * square * px_per_mm."""
    w_mm, h_mm = board.size_mm
    size = (round(w_mm * px_per_mm), round(h_mm * px_per_mm))
    if board.type == "charuco":
        try:
            return board.charuco().generateImage(size, marginSize=0, borderBits=1)
        except cv2.error:
            # OpenCV rounds a marker's place in a square of a fractional size past the image at some
            # sizes (a board of measured, non-whole squares): drawn at whole pixels a square, resized
            # (some whole sizes round so too: the next few are tried)
            first = int(np.ceil(board.square_mm * px_per_mm))
            for sq in range(first, first + 16):
                try:
                    whole = board.charuco().generateImage((board.squares_x * sq, board.squares_y * sq),
                                                          marginSize=0, borderBits=1)
                except cv2.error:
                    continue
                return cv2.resize(whole, size, interpolation=cv2.INTER_AREA)
            raise
    # A chessboard: the top-left square black, as OpenCV's own pattern.
    ys, xs = np.mgrid[0 : size[1], 0 : size[0]]
    cell = ((xs / px_per_mm // board.square_mm) + (ys / px_per_mm // board.square_mm)) % 2
    return np.where(cell == 0, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class BoardView:
    """The board's corners found in one photo.

    Attributes
    ----------
    image_points : ndarray, shape (N, 2), float64
        Image (x, y) px of the corners found.
    object_points : ndarray, shape (N, 3), float64
        The same corners in the board's frame, mm.
    ids : ndarray, shape (N,), int
        Corner ids (OpenCV's order: row by row from the top-left inner corner).
    """

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)


def _gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image if image.dtype == np.uint8 else np.clip(image, 0, 255).astype(np.uint8)
    gray = cv2.cvtColor(np.clip(image, 0, 255).astype(np.uint8), cv2.COLOR_RGB2GRAY)
    return np.asarray(gray, dtype=np.uint8)


def find_board_corners(image: np.ndarray, board: BoardSpec, *, beside_one_marker: bool = False
                       ) -> BoardView | None:
    """The board's corners in `image` (RGB (H, W, 3) or gray (H, W)), or None when fewer than
    ``MIN_CORNERS`` show (a chessboard: when not every inner corner shows).

    beside_one_marker : where fewer than ``_ENOUGH_CORNERS`` are found between two markers, also
        the corners beside one marker found (a hand-held photo whose part hides markers). Off for
        a station: its re-registration is better from fewer corners placed by two markers each
        (a 165 mm part over the board was re-registered wrong from single-marker corners)."""
    gray = _gray(image)
    if board.type == "chessboard":
        from prismcore.geometry.calibration import find_board

        corners = find_board(np.dstack([gray] * 3), board.inner_corners)
        if corners is None:
            return None
        ids: np.ndarray = np.arange(len(corners))
        return BoardView(np.asarray(corners, np.float64), board.corner_points(), ids)
    detector = cv2.aruco.CharucoDetector(board.charuco())
    corners, ids, _, _ = detector.detectBoard(gray)
    if beside_one_marker and (ids is None or len(ids) < _ENOUGH_CORNERS):
        # A part over the board hides markers: a corner beside one marker found (not two) is
        # placed by that marker alone; taken only where the default finds too few to use.
        params = cv2.aruco.CharucoParameters()
        params.minMarkers = 1
        more, more_ids, _, _ = cv2.aruco.CharucoDetector(board.charuco(), params).detectBoard(gray)
        if more_ids is not None and (ids is None or len(more_ids) > len(ids)):
            corners, ids = more, more_ids
    if ids is None or len(ids) < MIN_CORNERS:
        return None
    ids = ids.ravel().astype(int)
    return BoardView(corners.reshape(-1, 2).astype(np.float64), board.corner_points()[ids], ids)

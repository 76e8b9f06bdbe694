"""Hand-held, no station: the board lying around the part gives this photo's support plane, pose
and scale (and the focal length when no camera is given), and the part is found against the
board's own known pattern, drawn where the board lies and lit as the photo shows it.
"""

from __future__ import annotations

import time
from typing import cast

import cv2
import numpy as np

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.station import background
from prismcore.station.background import board_cover, shadow_difference, smooth_level, table_zone, with_table
from prismcore.station.board import BoardSpec, BoardView, board_image, find_board_corners
from prismcore.station.calibrate import MAX_RMS_PX, MIN_PLANE_CORNERS, board_pose
from prismcore.station.measure import StationMeasurement, measure_registered
from prismcore.station.registration import Registration
from prismcore.station.segment import SHADOW_RANGE, norm2, planes, shadow_ratio
from prismcore.station.sheet import ink_strokes, sheet_margins
from prismcore.station.undistort import undistorter

__all__ = ["board_camera", "expected_board", "measure_on_board", "shadow_floor"]

_LEVEL_SQUARES = 0.7  # the light's level is smoothed over this many squares
_DIFFERS = 25.0  # RGB levels (after the shadow's scale): a pixel this far from the board is not the board's
_MAX_K1 = 0.5  # a radial distortion beyond this from one view of a board is not trusted
_PATTERN_PX = 3.0  # the pattern is drawn at this many of its pixels per photo pixel, then averaged
_SHADOW_TOLERANCE = 0.7  # a shadow darkens the board's white at least this share as much as its black
_MAX_FLOOR = 0.9  # the least scale a pixel's shadow is held to, at most
_LIT = 0.85  # a square this much darker than the board's light nearby is in a shadow
_LIT_PASSES = 3  # the light found again without the shadowed squares (each pass nearer the lit)
_BLACK_LIT = 1.5  # a black square's pixel brighter than this against the plate's black is not lit so
_INK_MM = 1.5  # the print on the sheet's margin (ruler, text) is strokes thinner than this
_STRAY = 4.0  # a board corner missed by this many times the corners' median miss is a stray
_STRAY_PX = 1.5  # (and by over this many px)
_MAX_STRAYS = 0.2  # at most this share of the corners left out as strays
_TOUCH_PX = 13  # a blob this near the board's squares (px) touches them


def _board_view(photo: np.ndarray, board: BoardSpec) -> BoardView:
    view = find_board_corners(photo, board, beside_one_marker=True)
    if view is None or len(view) < MIN_PLANE_CORNERS:
        found = 0 if view is None else len(view)
        raise InputError(
            f"{found} board corners found, at least {MIN_PLANE_CORNERS} are needed: the board "
            "must show around the part (a part as large as the board hides it: print a larger one, "
            "prism board --paper A3; a board far off shows its markers too small: come closer)"
        )
    return view


def _fit_flags(radial: bool) -> int:
    return (
        cv2.CALIB_USE_INTRINSIC_GUESS
        | cv2.CALIB_FIX_PRINCIPAL_POINT
        | cv2.CALIB_FIX_ASPECT_RATIO
        | cv2.CALIB_ZERO_TANGENT_DIST
        | cv2.CALIB_FIX_K2
        | cv2.CALIB_FIX_K3
        | (0 if radial else cv2.CALIB_FIX_K1)
    )


def _one_view_fit(view: BoardView, size: tuple[int, int], radial: bool = True
                  ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(RMS px, K, distortion, each corner's miss (N,) px) of the camera fitted to one view."""
    w, h = size
    K0 = np.array([[max(w, h), 0, (w - 1) / 2], [0, max(w, h), (h - 1) / 2], [0, 0, 1]], np.float64)
    obj = [view.object_points.astype(np.float32)]
    img = [view.image_points.astype(np.float32)]
    rms, K, dist, rv, tv, _, _, _ = cv2.calibrateCameraExtended(obj, img, (w, h), K0, np.zeros(5),
                                                                 flags=_fit_flags(radial))
    seen, _ = cv2.projectPoints(obj[0], rv[0], tv[0], K, dist)
    return float(rms), K, dist, np.linalg.norm(seen.reshape(-1, 2) - view.image_points, axis=1)


def without_strays(view: BoardView, size: tuple[int, int]) -> BoardView:
    """`view` without the corners its own one-view fit misses by over _STRAY times the corners'
    median miss (and over _STRAY_PX): a corner refined onto a part's edge beside it, or read
    through a marker half hidden. At most _MAX_STRAYS of the corners are left out, and never
    below MIN_PLANE_CORNERS; a view whose misses are all alike is kept whole."""
    if len(view) <= MIN_PLANE_CORNERS:
        return view
    try:
        _, _, _, miss = _one_view_fit(view, size)
    except cv2.error:
        return view
    stray = miss > max(_STRAY_PX, _STRAY * float(np.median(miss)))
    left = len(view) - int(stray.sum())
    if not stray.any() or stray.sum() > _MAX_STRAYS * len(view) or left < MIN_PLANE_CORNERS:
        return view
    keep = ~stray
    return BoardView(view.image_points[keep], view.object_points[keep], view.ids[keep])


def board_camera(
    photo: np.ndarray, board: BoardSpec, view: BoardView | None = None, *, radial: bool = True
) -> CameraModel:
    """The camera from one photo of the board: the focal length and the lens's first radial
    distortion term k1, the principal point at the image's centre (a planar target in one view
    fixes the focal length and k1 with the centre known, not more). radial=False fixes k1 at 0.

    On renders with k1 = +-0.05 (k2 = 0) the sizes found with k1 fixed at 0 differ from those of
    a lens without distortion by under 0.1 % on average (benchmarks/station.py --lens-bias, see
    docs/explanation/accuracy.md); k1 is found (within about 0.015 there) so that a stronger lens
    (k1 -0.15 to -0.2, whose corners missed a pose without it by over 1 px) is measured, not refused.

    Raises
    ------
    InputError
        Too few corners, a board seen square-on (the focal length undetermined), a poor fit.
    """
    h, w = photo.shape[:2]
    view = _board_view(photo, board) if view is None else view
    rms, K, dist, _ = _one_view_fit(view, (w, h), radial)
    k1 = float(np.ravel(dist)[0])
    f = float(K[0, 0])
    if not (np.isfinite(f) and 0.2 * max(w, h) < f < 20 * max(w, h)):
        raise InputError(
            "the focal length could not be found from the board (seen square-on?): tilt the "
            "camera 30-60 degrees from the board, or give --camera camera.json"
        )
    if rms > MAX_RMS_PX or not abs(k1) <= _MAX_K1:
        raise InputError(
            f"the board's corners miss their fitted pose by {rms:.2f} px RMS (over {MAX_RMS_PX} px) "
            f"with the lens's distortion k1 {k1:+.3f} found from them: a lens with strong or complex "
            "distortion needs --camera camera.json (prism calibrate)"
            if rms > MAX_RMS_PX else
            f"the lens's distortion found from the board (k1 {k1:+.2f}) is beyond {_MAX_K1}: a wide-angle "
            "lens needs --camera camera.json (prism calibrate)"
        )
    return CameraModel(
        fx=f,
        fy=f,
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        dist=[k1, 0.0, 0.0, 0.0, 0.0],
        image_width=w,
        image_height=h,
        rms_px=float(rms),
        name="from the board in the photo",
    )


Margins = tuple[float, float, float, float]
"""The sheet's paper past the board's (left, top, right, bottom) sides, mm (:func:`sheet_margins`)."""
_NO_MARGIN: Margins = (0.0, 0.0, 0.0, 0.0)


def _corners(board: BoardSpec, pose_h: np.ndarray, margins: Margins = _NO_MARGIN
             ) -> tuple[np.ndarray, np.ndarray]:
    """The four corners (4, 2) of the board with `margins` of its sheet, in mm on the board and in
    px in the undistorted photo (through the homography `pose_h`), in order round it."""
    bw, bh = board.size_mm
    left, top, right, bottom = margins
    x0, y0, x1, y1 = -left, -top, bw + right, bh + bottom
    corners_mm = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
    return corners_mm, cv2.perspectiveTransform(corners_mm.reshape(-1, 1, 2), pose_h).reshape(-1, 2)


def expected_board(
    photo_u: np.ndarray, board: BoardSpec, camera: CameraModel, pose_h: np.ndarray,
    notes: list[str] | None = None, margins: Margins = _NO_MARGIN,
) -> tuple[np.ndarray, np.ndarray]:
    """The support as it would look without the part: the board's pattern drawn where the board
    lies (homography `pose_h`: board mm -> undistorted photo px), its white and black lit as the
    photo's own white and black squares are lit nearby, and the sheet's white paper `margins`
    (mm) round it lit as the white squares, its print (ruler, text: strokes under _INK_MM) taken
    as the photo shows it; elsewhere the photo itself (no part is looked for there). Returns
    (plate (H, W, 3) uint8, the board's and the sheet's region (H, W) bool); a fallback that may
    change the outline is said in `notes`.

    The light is found without what differs from the board (a part), a dark part over white
    squares told from a shadow by the black squares nearby (:func:`shadow_floor`), and without the
    squares a shadow darkens: the board is modelled lit, the shadow left to the segmentation's
    scale (a shadow's edge within the light's smoothing made the plate darker than the photo on
    its lit side)."""
    notes = [] if notes is None else notes
    h, w = photo_u.shape[:2]
    # Pixels of the pattern per mm so that one photo pixel covers ~_PATTERN_PX of them.
    _, corners_px = _corners(board, pose_h)
    span_px = max(
        np.linalg.norm(corners_px[1] - corners_px[0]), np.linalg.norm(corners_px[2] - corners_px[1])
    )
    ppm = float(np.clip(_PATTERN_PX * span_px / max(board.size_mm), 1.0, 20.0))
    left, top, right, bottom = (round(m * ppm) for m in margins)
    art = cv2.copyMakeBorder(board_image(board, ppm), top, bottom, left, right, cv2.BORDER_CONSTANT,
                             value=255).astype(np.float32) / 255.0
    # pattern pixel centres at (i + 0.5) / ppm mm, from the sheet's corner (-left, -top) px
    S = np.array([[1 / ppm, 0, (0.5 - left) / ppm], [0, 1 / ppm, (0.5 - top) / ppm], [0, 0, 1]])
    to_photo = pose_h @ S
    pattern = cv2.warpPerspective(art, to_photo, (w, h), flags=cv2.INTER_LINEAR)
    region = cv2.warpPerspective(np.ones_like(art), to_photo, (w, h), flags=cv2.INTER_NEAREST) > 0.5
    pattern = cv2.GaussianBlur(pattern, (0, 0), 0.7)
    drawn = np.where(region, pattern, 1.0).astype(np.float32)
    square_px = float(span_px / max(board.squares_x, board.squares_y))
    sigma = max(2.0, float(_LEVEL_SQUARES * square_px))
    # The board's box in the photo only: elsewhere the plate is the photo itself.
    plate_u = photo_u.copy()
    x, y, bw, bh = cv2.boundingRect(region.astype(np.uint8))
    if bw == 0:
        return plate_u, region
    win = (slice(y, y + bh), slice(x, x + bw))
    P = photo_u[win].astype(np.float32)
    reg, pat = region[win], pattern[win]
    inner = cv2.erode(reg.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    weights = []
    levels = []
    for sel in (pat > 0.85, pat < 0.15):
        m = (sel & inner).astype(np.float32)
        level = smooth_level(P, m, sigma)
        # Again without the pixels far from that first level: the part's own colour, where it
        # covers white (or black) squares, is not the squares' light.
        close = norm2(planes(P - level)) < np.square(0.25 * (np.sqrt(norm2(planes(level))) + 40))
        weights.append(m * close)
        levels.append(smooth_level(P, m * close, sigma))
    white, black = levels
    plate = black + (white - black) * pat[..., None]
    # And again without what that board differs from (a part large against the squares pulls
    # their light towards its colour): the squares' light from the squares alone. A shadow is
    # held to darken the white as the black squares nearby show (:func:`shadow_floor`): a dark
    # part over white squares differs, not taken for a shadow's white.
    floor = shadow_floor(P, plate, drawn[win], square_px)
    # (and the board lit up to _BLACK_LIT times that board's light is the board: the light's
    # edge lies within the smoothing)
    differs = shadow_difference(P, plate, (floor, _BLACK_LIT)) > _DIFFERS
    differs = cv2.dilate(differs.astype(np.uint8), np.ones((5, 5), np.uint8)) == 0
    # And the light without the shadow: the squares darker than that board by a shadow's least
    # left out too, so that the board is modelled lit where the shadow's edge lies within the
    # smoothing (the lit side was darker than the photo: a lit marker beside a shadow read as a
    # second part); the shadow is the segmentation's scale.
    lit = np.ones_like(differs)
    for _ in range(_LIT_PASSES):
        white, black = (_hue(smooth_level(P, wgt * differs * lit, sigma), P, wgt, notes) for wgt in weights)
        plate = black + (white - black) * pat[..., None]
        lit = shadow_ratio(planes(P), planes(plate)) >= _LIT
    plate_u[win] = np.where(reg[..., None], np.clip(plate, 0, 255), P).astype(np.uint8)
    if any(margins):
        margin = region & (board_cover(corners_px, (h, w), 0.0) < 0.5)
        ink = ink_strokes(photo_u, margin, float(_INK_MM * span_px / max(board.size_mm)))
        plate_u[ink] = photo_u[ink]
    return plate_u, region


def shadow_floor(photo_u: np.ndarray, plate_u: np.ndarray, pattern: np.ndarray, square_px: float
                 ) -> np.ndarray:
    """The least a shadow may scale the board at each pixel, from its black squares nearby: (H, W)
    float32.

    A shadow scales the board's white and black alike (it takes a share of the light off both),
    and keeps its pattern; a dark part hides it: over the white squares it is as dark as a deep
    shadow, over the black ones as bright as the black or brighter. So the scale the black squares
    show near a pixel (photo `photo_u` on plate `plate_u`, (H, W, 3); `pattern` (H, W) < 0.1: the
    plate's black; a black pixel over _BLACK_LIT times the plate's left out: a part that bright
    over it is no light's evidence), its least over a quarter of a square (`square_px`, px) round
    it (a shadow's edge), _SHADOW_TOLERANCE times over, is the least a shadow darkens that pixel;
    away from the board's black, SHADOW_RANGE's least.
    """
    h, w = pattern.shape
    P, B = photo_u.astype(np.float32), plate_u.astype(np.float32)
    ratio = shadow_ratio(planes(P), planes(B))
    dark = cv2.erode((pattern < 0.1).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(np.float32)
    dark *= ratio < _BLACK_LIT
    sigma = max(1.5, 0.15 * square_px)
    f = float(min(1.0, 2.0 / sigma))
    small = (max(1, round(w * f)), max(1, round(h * f)))
    num = cv2.GaussianBlur(cv2.resize(ratio * dark, small, interpolation=cv2.INTER_AREA), (0, 0), sigma * f)
    den = cv2.GaussianBlur(cv2.resize(dark, small, interpolation=cv2.INTER_AREA), (0, 0), sigma * f)
    scale = np.where(den > 0.05, num / np.maximum(den, 1e-6), SHADOW_RANGE[0] / _SHADOW_TOLERANCE)
    k = max(3, round(0.5 * square_px * f) | 1)
    least = cv2.erode(scale.astype(np.float32), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    floor = np.clip(_SHADOW_TOLERANCE * least, SHADOW_RANGE[0], _MAX_FLOOR).astype(np.float32)
    return cast("np.ndarray", cv2.resize(floor, (w, h), interpolation=cv2.INTER_LINEAR))


def _hue(level: np.ndarray, P: np.ndarray, weight: np.ndarray, notes: list[str]) -> np.ndarray:
    """`level` (H, W, 3) with its colour's direction made the board's own for that print, the
    median over all its squares (a part is a minority of them), its brightness kept: a part whose
    colour pulled the squares' light near it towards its own differs from them again. Under 100
    of its pixels seen: `level` as it is, said in `notes`."""
    sel = weight > 0
    if sel.sum() < 100:
        note = (f"only {int(sel.sum())} pixels of the board's squares of one print seen (under 100): "
                "their colour not checked against a part's nearby; the part's outline may be off")
        if note not in notes:
            notes.append(note)
        return level
    colours = P[sel]
    hue = np.median(colours / (np.linalg.norm(colours, axis=1, keepdims=True) + 1.0), axis=0)
    hue = hue / max(float(np.linalg.norm(hue)), 1e-6)
    return cast("np.ndarray", np.sqrt(norm2(planes(level)))[..., None] * hue.astype(np.float32))


def measure_on_board(
    photo: np.ndarray, board: BoardSpec, camera: CameraModel | None = None
) -> StationMeasurement:
    """Measure the one box resting on the board in a hand-held `photo` (RGB (H, W, 3) uint8).

    camera : known intrinsics and lens; else the focal length is found from the board.

    Raises
    ------
    InputError
        Too few board corners, no focal length, and as :func:`measure_on_station` (no part, two
        parts, not a box resting flat), or a part reaching over the board's edge.
    """
    t0 = time.perf_counter()
    h, w = photo.shape[:2]
    view = _board_view(photo, board)
    if camera is None:  # (strays are judged by the free one-view fit: a given lens may need more)
        view = without_strays(view, (w, h))
    cam = board_camera(photo, board, view) if camera is None else camera.for_size(w, h)
    photo_u = undistorter(cam).image(photo)
    pose = board_pose(view, cam)
    K = cam.matrix()
    R, t = pose.rotation(), pose.translation()
    pose_h = K @ np.column_stack([R[:, 0], R[:, 1], t])
    t1 = time.perf_counter()
    notes: list[str] = []
    # The sheet the board is printed on, as far as its paper shows round the board: modelled as
    # paper (a part may stand on it), not as the table.
    margins = sheet_margins(photo_u, board, pose_h)
    plate_u, region = expected_board(photo_u, board, cam, pose_h, notes, margins)
    # The table round the sheet from the photo itself: a part rising past the sheet's edge in
    # the photo is outlined against the table there.
    corners_mm, corners_px = _corners(board, pose_h, margins)
    tall = background.TABLE_HEIGHT * max(board.size_mm)
    # a part over the sheet's edge reaches past it by up to its own size, and rises there too
    grown = corners_mm + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64) * tall
    zone = table_zone(grown, K, R, t, tall)
    cover = board_cover(corners_px, (h, w))
    plate_u, region, table_notes = with_table(photo_u, plate_u, cover, zone)
    # The part rests on the board's squares (or over their edge): what differs only away from them,
    # on the sheet's margin or past it, is the table's (a printed cloth's pattern the median
    # missed), the sheet's edge modelled short, or another object's, not the part.
    rests_on = cv2.dilate((board_cover(_corners(board, pose_h)[1], (h, w)) > 0.5).astype(np.uint8),
                          np.ones((_TOUCH_PX, _TOUCH_PX), np.uint8)) > 0
    reg = Registration(pose, np.eye(3), 0.0, "board", len(view))
    timings = {
        "undistort": 0.0,
        "register": (t1 - t0) * 1e3,
        "expected_board": (time.perf_counter() - t1) * 1e3,
    }
    measured = measure_registered(
        photo_u, plate_u, cam, reg, timings, region=region, rests_on=rests_on,
        region_refusal=(
            "the part's outline reaches past the board and the table modelled round it in the photo "
            f"(where a part up to {tall:.0f} mm tall on the board shows): lay the part on the board "
            "with the board all round it, and photograph from higher up or use a larger board"
        ),
    )
    measured.warnings.extend([*notes, *table_notes])
    if camera is None:
        measured.warnings.append(
            f"focal length {cam.fx:.0f} px and lens distortion k1 {cam.dist[0]:+.3f} found from the "
            "board in the photo (no --camera; the principal point taken at the centre)"
        )
    return measured

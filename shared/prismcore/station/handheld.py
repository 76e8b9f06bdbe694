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
from prismcore.station.background import board_cover, shadow_difference, table_zone, with_table
from prismcore.station.board import BoardSpec, BoardView, board_image, find_board_corners
from prismcore.station.calibrate import MAX_RMS_PX, MIN_PLANE_CORNERS, board_pose
from prismcore.station.measure import StationMeasurement, measure_registered
from prismcore.station.segment import Registration, undistorter

__all__ = ["board_camera", "expected_board", "measure_on_board"]

_LEVEL_SQUARES = 0.7  # the light's level is smoothed over this many squares
_DIFFERS = 25.0  # RGB levels (after the shadow's scale): a pixel this far from the board is not the board's
_MAX_K1 = 0.5  # a radial distortion beyond this from one view of a board is not trusted
_PATTERN_PX = 3.0  # the pattern is drawn at this many of its pixels per photo pixel, then averaged


def _board_view(photo: np.ndarray, board: BoardSpec) -> BoardView:
    view = find_board_corners(photo, board)
    if view is None or len(view) < MIN_PLANE_CORNERS:
        found = 0 if view is None else len(view)
        raise InputError(
            f"{found} board corners found, at least {MIN_PLANE_CORNERS} are needed: the board "
            "must show around the part"
        )
    return view


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
    K0 = np.array([[max(w, h), 0, (w - 1) / 2], [0, max(w, h), (h - 1) / 2], [0, 0, 1]], np.float64)
    flags = (
        cv2.CALIB_USE_INTRINSIC_GUESS
        | cv2.CALIB_FIX_PRINCIPAL_POINT
        | cv2.CALIB_FIX_ASPECT_RATIO
        | cv2.CALIB_ZERO_TANGENT_DIST
        | cv2.CALIB_FIX_K2
        | cv2.CALIB_FIX_K3
        | (0 if radial else cv2.CALIB_FIX_K1)
    )
    obj = [view.object_points.astype(np.float32)]
    img = [view.image_points.astype(np.float32)]
    rms, K, dist, _, _, _, _, _ = cv2.calibrateCameraExtended(obj, img, (w, h), K0, np.zeros(5), flags=flags)
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


def expected_board(
    photo_u: np.ndarray, board: BoardSpec, camera: CameraModel, pose_h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The support as it would look without the part: the board's pattern drawn where the board
    lies (homography `pose_h`: board mm -> undistorted photo px), its white and black lit as the
    photo's own white and black squares are lit nearby; elsewhere the photo itself (no part is
    looked for there). Returns (plate (H, W, 3) uint8, board region (H, W) bool)."""
    h, w = photo_u.shape[:2]
    # Pixels of the pattern per mm so that one photo pixel covers ~_PATTERN_PX of them.
    corners_mm = np.array(
        [[0, 0], [board.size_mm[0], 0], [board.size_mm[0], board.size_mm[1]], [0, board.size_mm[1]]],
        np.float64,
    )
    corners_px = cv2.perspectiveTransform(corners_mm.reshape(-1, 1, 2), pose_h).reshape(-1, 2)
    span_px = max(
        np.linalg.norm(corners_px[1] - corners_px[0]), np.linalg.norm(corners_px[2] - corners_px[1])
    )
    ppm = float(np.clip(_PATTERN_PX * span_px / max(board.size_mm), 1.0, 20.0))
    art = board_image(board, ppm).astype(np.float32) / 255.0
    # pattern pixel centres at (i + 0.5) / ppm mm
    S = np.array([[1 / ppm, 0, 0.5 / ppm], [0, 1 / ppm, 0.5 / ppm], [0, 0, 1]])
    to_photo = pose_h @ S
    pattern = cv2.warpPerspective(art, to_photo, (w, h), flags=cv2.INTER_LINEAR)
    region = cv2.warpPerspective(np.ones_like(art), to_photo, (w, h), flags=cv2.INTER_NEAREST) > 0.5
    pattern = cv2.GaussianBlur(pattern, (0, 0), 0.7)
    square_px = span_px / max(board.squares_x, board.squares_y)
    sigma = max(2.0, float(_LEVEL_SQUARES * square_px))
    P = photo_u.astype(np.float32)
    inner = cv2.erode(region.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    weights = []
    levels = []
    for sel in (pattern > 0.85, pattern < 0.15):
        m = (sel & inner).astype(np.float32)
        level = _smooth(P, m, sigma)
        # Again without the pixels far from that first level: the part's own colour, where it
        # covers white (or black) squares, is not the squares' light.
        close = np.linalg.norm(P - level, axis=2) < 0.25 * (np.linalg.norm(level, axis=2) + 40)
        weights.append(m * close)
        levels.append(_smooth(P, m * close, sigma))
    white, black = levels
    plate = black + (white - black) * pattern[..., None]
    # And again without what that board differs from (a part large against the squares pulls
    # their light towards its colour): the squares' light from the squares alone.
    differs = shadow_difference(P, plate) > _DIFFERS
    differs = cv2.dilate(differs.astype(np.uint8), np.ones((5, 5), np.uint8)) == 0
    white, black = (_hue(_smooth(P, wgt * differs, sigma), P, wgt) for wgt in weights)
    plate = black + (white - black) * pattern[..., None]
    plate = np.where(region[..., None], plate, P)
    return np.clip(plate, 0, 255).astype(np.uint8), region


def _hue(level: np.ndarray, P: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """`level` (H, W, 3) with its colour's direction made the board's own for that print, the
    median over all its squares (a part is a minority of them), its brightness kept: a part whose
    colour pulled the squares' light near it towards its own differs from them again."""
    sel = weight > 0
    if sel.sum() < 100:
        return level
    colours = P[sel]
    hue = np.median(colours / (np.linalg.norm(colours, axis=1, keepdims=True) + 1.0), axis=0)
    hue = hue / max(float(np.linalg.norm(hue)), 1e-6)
    return cast("np.ndarray", np.linalg.norm(level, axis=2, keepdims=True) * hue.astype(np.float32))


def _smooth(P: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """Normalised convolution: the weighted mean colour near each pixel, computed on a copy
    reduced to a few pixels a sigma (the light varies slowly) and brought back up."""
    h, w = weight.shape
    f = float(min(1.0, 3.0 / sigma))
    small = (max(1, round(w * f)), max(1, round(h * f)))
    Ps = cv2.resize(P * weight[..., None], small, interpolation=cv2.INTER_AREA)
    Ws = cv2.resize(weight, small, interpolation=cv2.INTER_AREA)
    s = sigma * f
    num, den = cv2.GaussianBlur(Ps, (0, 0), s), cv2.GaussianBlur(Ws, (0, 0), s)
    far, far_den = cv2.GaussianBlur(Ps, (0, 0), 4 * s), cv2.GaussianBlur(Ws, (0, 0), 4 * s)
    near = num / np.maximum(den, 1e-6)[..., None]
    wide = far / np.maximum(far_den, 1e-6)[..., None]
    # where no such square lies near (under the part), the wider neighbourhood's light
    level = np.where((den > 0.05)[..., None], near, wide).astype(np.float32)
    return cast("np.ndarray", cv2.resize(level, (w, h), interpolation=cv2.INTER_LINEAR))


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
    cam = board_camera(photo, board, view) if camera is None else camera.for_size(w, h)
    photo_u = undistorter(cam).image(photo)
    pose = board_pose(view, cam)
    K = cam.matrix()
    R, t = pose.rotation(), pose.translation()
    pose_h = K @ np.column_stack([R[:, 0], R[:, 1], t])
    t1 = time.perf_counter()
    plate_u, region = expected_board(photo_u, board, cam, pose_h)
    # The table round the board from the photo itself: a part rising past the board's edge in
    # the photo is outlined against the table there.
    corners_mm = np.array([[0, 0], [board.size_mm[0], 0], [board.size_mm[0], board.size_mm[1]],
                           [0, board.size_mm[1]]], np.float64)
    corners_px = cv2.perspectiveTransform(corners_mm.reshape(-1, 1, 2), pose_h).reshape(-1, 2)
    tall = background.TABLE_HEIGHT * max(board.size_mm)
    zone = table_zone(corners_mm, K, R, t, tall)
    plate_u, region = with_table(photo_u, plate_u, board_cover(corners_px, (h, w)), zone)
    reg = Registration(pose, np.eye(3), 0.0, "board", len(view))
    timings = {
        "undistort": 0.0,
        "register": (t1 - t0) * 1e3,
        "expected_board": (time.perf_counter() - t1) * 1e3,
    }
    measured = measure_registered(
        photo_u, plate_u, cam, reg, timings, region=region,
        region_refusal=(
            "the part's outline reaches past the board and the table modelled round it in the photo "
            f"(where a part up to {tall:.0f} mm tall on the board shows): lay the part on the board "
            "with the board all round it, and photograph from higher up or use a larger board"
        ),
    )
    if camera is None:
        measured.warnings.append(
            f"focal length {cam.fx:.0f} px and lens distortion k1 {cam.dist[0]:+.3f} found from the "
            "board in the photo (no --camera; the principal point taken at the centre)"
        )
    return measured

"""Where the camera is now against where it was calibrated: the support's pose in a photo and the
plate -> photo homography, from the board's corners found again or from the support's own
texture, and whether the camera moved at all.

Everything here works in the undistorted (pinhole) image of the station's camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.station.board import BoardSpec, find_board_corners
from prismcore.station.calibrate import MIN_PLANE_CORNERS, PlanePose, board_pose

__all__ = ["MAX_SHIFT_PX", "Registration", "register"]

MAX_SHIFT_PX = 25.0  # the camera moved further than this since calibration: refused


@dataclass(frozen=True)
class Registration:
    """Where the camera is now against where it was calibrated.

    pose : the support plane's pose now. homography : plate pixels -> photo pixels (undistorted).
    shift_px : how far the support moved in the image (median over the photo). source : what it
    was measured on: "board" (its corners found again), "plate" (the support's texture),
    "unmoved" (the plate's features found where they were: the calibration's pose and the
    identity kept, the shift what those features moved), "none" (no plate).
    """

    pose: PlanePose
    homography: np.ndarray
    shift_px: float
    source: str
    corners: int = 0


def _plane_h(K: np.ndarray, pose: PlanePose) -> np.ndarray:
    R, t = pose.rotation(), pose.translation()
    return cast("np.ndarray", K @ np.column_stack([R[:, 0], R[:, 1], t]))


def _shift(H: np.ndarray, size: tuple[int, int]) -> float:
    w, h = size
    grid = np.array([[x, y] for x in np.linspace(0, w - 1, 5) for y in np.linspace(0, h - 1, 5)], np.float64)
    moved = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), H).reshape(-1, 2)
    return float(np.median(np.linalg.norm(moved - grid, axis=1)))


def _pose_from_h(K: np.ndarray, H_plane: np.ndarray, ref: PlanePose) -> PlanePose:
    M = np.linalg.inv(K) @ H_plane
    scale = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    M = M * scale
    if M[2, 2] < 0:
        M = -M
    r1, r2 = M[:, 0], M[:, 1]
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    U, _, Vt = np.linalg.svd(R)
    R = U @ Vt
    rvec = cv2.Rodrigues(R)[0].ravel()
    return PlanePose(
        rvec=[float(v) for v in rvec],
        tvec=[float(v) for v in M[:, 2]],
        rms_px=ref.rms_px,
        corners=ref.corners,
    )


def register(
    photo_u: np.ndarray,
    plate_u: np.ndarray | None,
    photo: np.ndarray,
    board: BoardSpec,
    camera: CameraModel,
    calibrated: PlanePose,
) -> Registration:
    """The support's pose in `photo` and the plate -> photo homography: the calibration's as it is
    where the plate's features are found where they were ("unmoved"), else from the board's
    corners found again, else from the support's own texture.

    photo_u, plate_u : undistorted RGB (H, W, 3) uint8. photo : the photo as taken (the board's
    corners are found there, with the lens model, as at calibration).

    Raises
    ------
    InputError
        The camera moved more than ``MAX_SHIFT_PX``, or could not be re-registered.
    """
    K = camera.matrix()
    size = (photo_u.shape[1], photo_u.shape[0])
    H_cal = _plane_h(K, calibrated)
    still = None if plate_u is None else _unmoved(plate_u, photo_u)
    if still is not None:
        # A camera that stayed where it was calibrated (a station's, bolted down): the plate's
        # pose and pixels hold as they are. Re-found board corners, fewer where the part hides
        # them, placed the support 0.3-0.6 px off (up to 2 px: renders of a still camera),
        # enough for the board's squares to show as part. Its shift is what the still features
        # moved (under _STILL_PX): measured, not assumed 0.
        return Registration(calibrated, np.eye(3), still, "unmoved")
    view = find_board_corners(photo, board)
    if view is not None and len(view) >= MIN_PLANE_CORNERS:
        pose = board_pose(view, camera)
        if pose.rms_px <= 1.5:
            H = _plane_h(K, pose) @ np.linalg.inv(H_cal)
            shift = _shift(H, size)
            if shift > MAX_SHIFT_PX:
                raise InputError(
                    f"the camera moved {shift:.0f} px since calibration (over {MAX_SHIFT_PX:.0f} "
                    "px): calibrate the station again"
                )
            return Registration(pose, H, shift, "board", len(view))
    if plate_u is None:
        return Registration(calibrated, np.eye(3), 0.0, "none")
    # The support's own texture: corners of the plate tracked into the photo (pyramidal Lucas-
    # Kanade, checked forward and back), a homography through them by RANSAC. The part and its
    # shadow hide some; the rest move as the camera turned.
    tracked = _track_plate(plate_u, photo_u)
    if tracked is None:
        tracked = _ecc_plate(plate_u, photo_u)
    if tracked is None:
        raise InputError(
            "the camera cannot be re-registered on the support: too few of its features were found again "
            "(it moved since calibration, or the support changed); calibrate again"
        )
    shift = _shift(tracked, size)
    if shift > MAX_SHIFT_PX:
        raise InputError(
            f"the camera moved {shift:.0f} px since calibration (over {MAX_SHIFT_PX:.0f} px): "
            "calibrate the station again"
        )
    return Registration(_pose_from_h(K, tracked @ H_cal, calibrated), tracked, shift, "plate")


_STILL_PX = 0.25  # a feature tracked within this of where it was has not moved
_STILL_BLUR = 1.5  # px, Gaussian sigma
_STILL_SHARE = 0.5  # of the features tracked: the support's, the part and its shadow hide the rest


def _unmoved(plate_u: np.ndarray, photo_u: np.ndarray) -> float | None:
    """How far the plate's features moved (px, the median of those within _STILL_PX) when most of
    them are found again where they were: the camera has not moved since calibration; None when
    it has (or too few features to tell). Tracked from where they were (pyramidal Lucas-Kanade),
    the photo's levels scaled to the plate's (the light's change)."""
    a = cv2.cvtColor(plate_u, cv2.COLOR_RGB2GRAY)
    b = cv2.cvtColor(photo_u, cv2.COLOR_RGB2GRAY)
    ratio = float(np.median(a)) / max(float(np.median(b)), 1.0)
    # Blurred: a noisy photo's (a path-traced render's, a dim room's) strongest "corners" at full
    # resolution are its noise, found nowhere in the other image (development renders: 14-44 %
    # of them within _STILL_PX, 57-98 % once blurred, of a camera that did not move).
    a = cv2.GaussianBlur(a, (0, 0), _STILL_BLUR)
    b = cv2.GaussianBlur(cv2.convertScaleAbs(b, alpha=ratio), (0, 0), _STILL_BLUR)
    found = cv2.goodFeaturesToTrack(a, _TRACK_POINTS, 0.05, 20, blockSize=15)
    if found is None or len(found) < _MIN_TRACKED:
        return None
    corners = np.asarray(found, np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    ahead, ok, _ = cv2.calcOpticalFlowPyrLK(a, b, corners, corners.copy(), winSize=(21, 21), maxLevel=1,
                                            criteria=criteria, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    tracked = ok.ravel() == 1
    moved = np.linalg.norm((ahead - corners).reshape(-1, 2), axis=1)
    still = tracked & (moved < _STILL_PX)
    if int(still.sum()) < max(_MIN_TRACKED, _STILL_SHARE * int(tracked.sum())):
        return None
    return float(np.median(moved[still]))


_TRACK_POINTS = 400
_MIN_TRACKED = 15  # features found again, both ways, within _FB_PX: fewer is no registration
_FB_PX = 0.5
_RANSAC_PX = 1.0


def _track_plate(plate_u: np.ndarray, photo_u: np.ndarray) -> np.ndarray | None:
    """The plate -> photo homography from the support's corners, or None when too few agree."""
    a = cv2.cvtColor(plate_u, cv2.COLOR_RGB2GRAY)
    b = cv2.cvtColor(photo_u, cv2.COLOR_RGB2GRAY)
    found = cv2.goodFeaturesToTrack(a, _TRACK_POINTS, 0.01, 20, blockSize=7)
    if found is None or len(found) < _MIN_TRACKED:
        return None
    corners = np.asarray(found, np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    ahead, ok1, _ = cv2.calcOpticalFlowPyrLK(a, b, corners, None, winSize=(21, 21), maxLevel=3,
                                             criteria=criteria)
    back, ok2, _ = cv2.calcOpticalFlowPyrLK(b, a, ahead, None, winSize=(21, 21), maxLevel=3,
                                            criteria=criteria)
    round_trip = np.linalg.norm((back - corners).reshape(-1, 2), axis=1)
    good = (ok1.ravel() == 1) & (ok2.ravel() == 1) & (round_trip < _FB_PX)
    if good.sum() < _MIN_TRACKED:
        return None
    H, inliers = cv2.findHomography(corners[good], ahead[good], cv2.RANSAC, _RANSAC_PX)
    if H is None or inliers is None or int(inliers.sum()) < _MIN_TRACKED:
        return None
    # refit on the inliers alone, least squares
    keep = inliers.ravel() == 1
    H, _ = cv2.findHomography(corners[good][keep], ahead[good][keep], 0)
    return None if H is None else cast("np.ndarray", H)


def _gray_scaled(image: np.ndarray, f: float) -> np.ndarray:
    """`image` (RGB) in gray, reduced by `f` (area-averaged), float32."""
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return cv2.resize(gray, None, fx=f, fy=f, interpolation=cv2.INTER_AREA).astype(np.float32)


def _ecc_plate(plate_u: np.ndarray, photo_u: np.ndarray) -> np.ndarray | None:
    """The plate -> photo homography by ECC on the support's texture (what changed masked out):
    slower than tracking (~0.4 s), for a support with too few corners to track."""
    small = 0.25
    a, b = _gray_scaled(plate_u, small), _gray_scaled(photo_u, small)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F))
    # ECC on the support alone: what changed (the part, its shadow) is left out.
    shifted = cv2.warpAffine(
        a, np.array([[1, 0, dx], [0, 1, dy]], np.float32), a.shape[::-1], borderMode=cv2.BORDER_REPLICATE
    )
    ratio = float(np.median(b)) / max(float(np.median(shifted)), 1.0)
    changed: np.ndarray = np.abs(b - ratio * shifted) > 12
    changed = cv2.dilate(changed.astype(np.uint8), np.ones((9, 9), np.uint8))
    valid = (changed == 0).astype(np.uint8)
    # ECC's warp maps the template's (the plate's) coordinates to the input's (the photo's).
    warp: np.ndarray = np.array([[1, 0, dx], [0, 1, dy], [0, 0, 1]], np.float32)
    try:
        cc, warp = cv2.findTransformECC(
            a,
            b,
            warp,
            cv2.MOTION_HOMOGRAPHY,
            (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 80, 1e-6),
            valid,
            5,
        )
    except cv2.error:
        cc = 0.0
    if cc >= 0.6:
        # Refined at half size: a quarter-size pixel is two pixels of the photo, and the board's
        # squares show a pixel's misregistration as a part.
        half = 0.5
        a2, b2 = _gray_scaled(plate_u, half), _gray_scaled(photo_u, half)
        up = np.diag([2.0, 2.0, 1.0])
        warp2: np.ndarray = (up @ warp.astype(np.float64) @ np.linalg.inv(up)).astype(np.float32)
        valid2 = cv2.resize(valid, a2.shape[::-1], interpolation=cv2.INTER_NEAREST)
        try:
            cc2, warp2 = cv2.findTransformECC(
                a2,
                b2,
                warp2,
                cv2.MOTION_HOMOGRAPHY,
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-6),
                valid2,
                3,
            )
            if cc2 >= cc - 0.05:
                small, warp = half, warp2
        except cv2.error:
            pass
    if cc < 0.6:
        return None
    S = np.diag([small, small, 1.0])
    return cast("np.ndarray", np.linalg.inv(S) @ warp.astype(np.float64) @ S)

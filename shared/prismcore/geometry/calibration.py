"""Camera calibration from photos of a chessboard: intrinsics and lens distortion.

:func:`find_board` finds the board's inner corners in one photo, :func:`calibrate` fits a
:class:`~prismcore.camera.CameraModel` to the corners of several photos (Zhang's method, as
OpenCV's ``calibrateCamera`` implements it), :func:`calibrate_images` chains the two over a
sequence of photos and checks that they share one size.

Corner detection: ``findChessboardCornersSB`` (Duda and Frese's localized radon transform), then
``cornerSubPix`` with a window sized from the board's own corner spacing. The classic
``findChessboardCorners`` + ``cornerSubPix`` with OpenCV's usual fixed 11 px half-window puts
corners of OpenCV's own photo ``left02.jpg`` (squares 22 px wide) 5-7 px off, pulled onto the
board's outer edge; that view alone lifts the published calibration of those photos to 0.39 px
RMS (1.18 px for the view). The SB detector's corners are right everywhere (within 0.15 px
median, 1.5 px at worst of those photos), so refining them in a window that cannot reach the
next corner cannot jump to another feature; the refinement halves their error on renders
(0.06 px against 0.13 px RMS) and brings those photos from 0.26 to 0.18 px RMS. The classic
detector is kept as a fallback for photos where SB finds nothing.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from prismcore.camera import CameraModel
from prismcore.errors import InputError

__all__ = ["MIN_VIEWS", "Calibration", "board_points", "calibrate", "calibrate_images", "find_board"]

MIN_VIEWS = 3  # Zhang's method: each view gives two constraints on the five intrinsics
_MAX_FOCAL_SIGMA = 0.05  # relative one-sigma of fx or fy above which the focal is not determined
_DETECT_MAX_SIDE = 2000  # px; SB detection on a larger photo runs on a downscaled copy (speed)
_REFINE_FRACTION = 0.35  # cornerSubPix half-window as a fraction of the smallest corner spacing
_REFINE_MAX_HALF = 40  # px; wider windows average more of a blurred corner, at some cost in time
_REFINE_MAX_MOVE = 0.5  # of the half-window; a corner refined further went astray (kept unrefined)
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 1e-3)


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`.

    Attributes
    ----------
    camera : CameraModel
        Intrinsics (px) and distortion (k1, k2, p1, p2, k3); ``rms_px`` is `rms_px` below.
    per_view_rms_px : ndarray, shape (V,), float64
        RMS reprojection error of each view used, px, in the order of `views`.
    rms_px : float
        RMS reprojection error over all corners of all views, px.
    views : tuple of str
        Names of the views used (the board was found), V of them.
    missing : tuple of str
        Names of the views without a board.
    focal_sigma_px : tuple of float
        One-sigma uncertainty of (fx, fy), px, from the fit's covariance.
    """

    camera: CameraModel
    per_view_rms_px: np.ndarray
    rms_px: float
    views: tuple[str, ...]
    missing: tuple[str, ...]
    focal_sigma_px: tuple[float, float]

    @property
    def views_used(self) -> int:
        return len(self.views)


def _check_board(board: tuple[int, int]) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in board)
    except (TypeError, ValueError):
        raise InputError(f"board {board!r}: expected (columns, rows) of inner corners") from None
    if cols < 3 or rows < 3 or (cols, rows) != tuple(board):
        raise InputError(f"board {board!r}: expected at least 3x3 inner corners (whole numbers)")
    return cols, rows


def board_points(board: tuple[int, int], square_mm: float) -> np.ndarray:
    """The board's inner corners in its own plane, in the order :func:`find_board` returns them.

    Returns
    -------
    ndarray, shape (cols * rows, 3), float32
        (x, y, 0) mm; x along a row (fastest), y down the columns.
    """
    cols, rows = _check_board(board)
    if not (np.isfinite(square_mm) and square_mm > 0):
        raise InputError(f"square size {square_mm!r} mm: expected a positive number")
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * float(square_mm)
    return np.column_stack([grid, np.zeros(len(grid))]).astype(np.float32)


def _gray(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 8 or a.shape[1] < 8:
        raise InputError(f"expected an RGB image of shape (H, W, 3), got shape {a.shape}")
    if a.dtype != np.uint8:  # 16-bit photos arrive as float32 in 0..255 units (prismcore.io.images)
        a = np.clip(np.round(a.astype(np.float32)), 0, 255).astype(np.uint8)
    return cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)


def _min_spacing(corners: np.ndarray, board: tuple[int, int]) -> float:
    cols, rows = board
    grid = corners.reshape(rows, cols, 2)
    along = np.linalg.norm(np.diff(grid, axis=1), axis=2).min()
    down = np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
    return float(min(along, down))


def _detect_sb(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    h, w = gray.shape
    scale = max(h, w) / _DETECT_MAX_SIDE
    small = gray
    if scale > 1:
        small = cv2.resize(gray, (round(w / scale), round(h / scale)), interpolation=cv2.INTER_AREA)
    found, corners = cv2.findChessboardCornersSB(small, board, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    corners = corners.reshape(-1, 2).astype(np.float64)
    if scale > 1:  # pixel centres: x + 0.5 = s (x_small + 0.5), per axis
        sx, sy = w / small.shape[1], h / small.shape[0]
        corners = (corners + 0.5) * (sx, sy) - 0.5
    return corners


def _detect_classic(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, board, flags=flags)
    return corners.reshape(-1, 2).astype(np.float64) if found else None


def find_board(image: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """The chessboard's inner corners in one photo, to sub-pixel precision.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8 (or float32 in 0..255 units), RGB
    board : (int, int)
        Inner corners per row and per column (columns, rows), e.g. (9, 6) for a board of
        10 x 7 squares. Both at least 3.

    Returns
    -------
    ndarray, shape (columns * rows, 2), float32, or None
        Image (x, y) px of the corners row by row, in the order of :func:`board_points` (the
        board may be returned rotated by 180 degrees from one photo to the next, which a
        calibration absorbs); None when the whole board is not seen.
    """
    board = _check_board(board)
    gray = _gray(image)
    corners = _detect_sb(gray, board)
    if corners is None:
        corners = _detect_classic(gray, board)
        if corners is None:
            return None
    half = int(np.clip(_REFINE_FRACTION * _min_spacing(corners, board), 2, _REFINE_MAX_HALF))
    refined = cv2.cornerSubPix(gray, corners.astype(np.float32).reshape(-1, 1, 2), (half, half),
                               (-1, -1), _SUBPIX_CRITERIA).reshape(-1, 2).astype(np.float64)
    strayed = np.linalg.norm(refined - corners, axis=1) > _REFINE_MAX_MOVE * half
    refined[strayed] = corners[strayed]
    return refined.astype(np.float32)


def _radial_folds(camera: CameraModel) -> float | None:
    """Normalised radius where the radial distortion turns back inside the photo, or None.

    A polynomial fitted to boards that miss the photo's corners can reach a maximum of
    r_d(r) = r (1 + k1 r^2 + k2 r^4 + k3 r^6) before the corners: pixels beyond it have no
    undistorted position. Tangential terms are small and left out of this check.
    """
    k = list(camera.dist) + [0.0] * (5 - len(camera.dist))
    k1, k2, k3 = k[0], k[1], k[4]
    xs = (np.array([0.0, camera.image_width - 1.0]) - camera.cx) / camera.fx
    ys = (np.array([0.0, camera.image_height - 1.0]) - camera.cy) / camera.fy
    r_corner = float(np.sqrt(np.max(xs**2) + np.max(ys**2)))  # farthest photo corner, distorted
    r = np.linspace(0.0, 4.0 * r_corner, 4001)
    r_d = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    slope = 1 + 3 * k1 * r**2 + 5 * k2 * r**4 + 7 * k3 * r**6
    reached = np.flatnonzero(r_d >= r_corner)
    end = reached[0] if reached.size else len(r)
    turns = np.flatnonzero(slope[:end + 1] <= 0)
    if turns.size:
        return float(r[turns[0]])
    return None if reached.size else float(r[-1])


def _residuals_and_sigma(
    objps: list[np.ndarray], image_points: list[np.ndarray], rvecs: Sequence[np.ndarray],
    tvecs: Sequence[np.ndarray], K: np.ndarray, dist: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-view RMS (V,) px and one-sigma of the intrinsics (fx, fy, cx, cy, *dist), px and unitless.

    The covariance is the inverse of the Gauss-Newton normal matrix with the views' poses
    eliminated (Schur complement), scaled by the residual variance. OpenCV's own
    ``calibrateCameraExtended`` inverts that matrix by SVD, which zeroes a null direction
    instead of reporting it: boards all seen square-on leave focal length and distance
    interchangeable, yet it reports the focal length to +-0.6 px. Here a singular direction
    gives an infinite sigma.
    """
    n_int = 4 + len(dist)
    A = np.zeros((n_int, n_int))
    schur = np.zeros((n_int, n_int))
    per_view, squares, count = [], 0.0, 0
    for objp, pts, rvec, tvec in zip(objps, image_points, rvecs, tvecs, strict=True):
        proj, jac = cv2.projectPoints(objp, rvec, tvec, K, dist)
        res = (proj.reshape(-1, 2) - pts).ravel()
        per_view.append(np.sqrt(np.mean(res.reshape(-1, 2) ** 2) * 2))
        squares += float(res @ res)
        count += res.size
        J_ext, J_int = jac[:, :6], jac[:, 6:6 + n_int]
        B = J_int.T @ J_ext
        A += J_int.T @ J_int
        schur += B @ np.linalg.solve(J_ext.T @ J_ext, B.T)
    S = A - schur
    dof = count - n_int - 6 * len(objps)
    variance = squares / max(dof, 1)
    # Jacobi scaling first: fx (hundreds of px) and k3 (unitless, r^6) differ by many orders.
    d = np.sqrt(np.clip(np.diag(S), 1e-300, None))
    Sn = S / np.outer(d, d)
    eig = np.linalg.eigvalsh(Sn)
    if not np.all(np.isfinite(eig)) or eig[0] <= 1e-12 * eig[-1]:
        sigma = np.full(n_int, np.inf)
    else:
        sigma = np.sqrt(np.diag(np.linalg.inv(Sn)) * variance) / d
    return np.asarray(per_view), sigma


def calibrate(
    corner_sets: Sequence[np.ndarray | None],
    board: tuple[int, int],
    square_mm: float,
    image_size: tuple[int, int],
    *,
    names: Sequence[str] | None = None,
) -> Calibration:
    """Intrinsics and distortion (k1, k2, p1, p2, k3) from several views of one chessboard.

    Parameters
    ----------
    corner_sets : sequence of ndarray, shape (columns * rows, 2), or None
        Per photo, the corners :func:`find_board` returned (image (x, y) px); None for a photo
        without the board (named in the error when too few boards are left).
    board : (int, int)
        Inner corners (columns, rows).
    square_mm : float
        Side of one square, mm (sets the unit of the poses only; the intrinsics are in px).
    image_size : (int, int)
        (width, height) px of every photo.
    names : sequence of str, optional
        Names of the photos for messages and the result; "photo 1", "photo 2", ... by default.

    Returns
    -------
    Calibration

    Raises
    ------
    InputError
        Fewer than ``MIN_VIEWS`` boards (the message says how many of how many photos showed
        it and names the others); corners of the wrong shape or outside the image; a degenerate
        fit: the focal length undetermined (boards all seen square-on), a principal point
        outside the image, or a distortion that folds the image back on itself.
    """
    cols, rows = _check_board(board)
    objp = board_points((cols, rows), square_mm)
    try:
        width, height = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise InputError(f"image size {image_size!r}: expected (width, height) px") from None
    if width < 8 or height < 8:
        raise InputError(f"image size {image_size!r}: expected (width, height) of at least 8 px")
    names = [f"photo {i + 1}" for i in range(len(corner_sets))] if names is None else list(names)
    if len(names) != len(corner_sets):
        raise InputError(f"{len(names)} names for {len(corner_sets)} corner sets")

    used, missing, image_points = [], [], []
    for name, corners in zip(names, corner_sets, strict=True):
        if corners is None:
            missing.append(name)
            continue
        pts = np.asarray(corners, dtype=np.float64)
        if pts.shape != (cols * rows, 2) or not np.all(np.isfinite(pts)):
            raise InputError(f"{name}: expected {cols * rows} finite (x, y) corners of a {cols}x{rows} "
                             f"board, got an array of shape {pts.shape}")
        if np.any(pts < -0.5) or np.any(pts > (width - 0.5, height - 0.5)):
            raise InputError(f"{name}: corners outside the {width}x{height} px image "
                             f"(x {pts[:, 0].min():.1f}..{pts[:, 0].max():.1f}, "
                             f"y {pts[:, 1].min():.1f}..{pts[:, 1].max():.1f})")
        used.append(name)
        image_points.append(pts.astype(np.float32))
    if len(used) < MIN_VIEWS:
        not_found = f"; not in {', '.join(missing)}" if missing else ""
        raise InputError(f"the {cols}x{rows} board was found in {len(used)} of {len(names)} photos"
                         f"{not_found}; at least {MIN_VIEWS} are needed (a {cols}x{rows} board has "
                         f"{cols}x{rows} inner corners, {cols + 1}x{rows + 1} squares, all in view)")

    objps = [objp] * len(image_points)
    try:
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(objps, image_points, (width, height), None, None)
    except cv2.error as exc:
        raise InputError(f"calibration of {len(used)} views failed: degenerate views "
                         f"({str(exc).strip().splitlines()[-1]})") from None
    dist = np.ravel(dist)
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist)) and np.isfinite(rms)):
        raise InputError(f"calibration of {len(used)} views is degenerate (non-finite result); "
                         "photograph the board at several tilts")
    per_view, sigma = _residuals_and_sigma(objps, image_points, rvecs, tvecs, K, dist)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    rel = max(sigma[0] / fx, sigma[1] / fy) if fx > 0 and fy > 0 else np.inf
    if rel > _MAX_FOCAL_SIGMA:
        spread = f"+-{rel:.0%}" if np.isfinite(rel) else "unbounded"
        raise InputError(f"calibration of {len(used)} views is degenerate: focal length {fx:.1f} px "
                         f"undetermined ({spread}); tilt the board by 20-40 degrees, differently "
                         "in each photo")
    if not (0 <= cx <= width - 1 and 0 <= cy <= height - 1):
        raise InputError(f"calibration of {len(used)} views is degenerate: principal point "
                         f"({cx:.1f}, {cy:.1f}) px outside the {width}x{height} image")
    camera = CameraModel(fx=fx, fy=fy, cx=cx, cy=cy, dist=[float(v) for v in dist],
                         image_width=width, image_height=height, rms_px=float(rms))
    fold = _radial_folds(camera)
    if fold is not None:
        raise InputError(f"calibration of {len(used)} views is degenerate: its lens distortion "
                         f"{[round(v, 4) for v in camera.dist]} folds the image back at normalised "
                         f"radius {fold:.2f}; include photos with the board near the image corners")
    return Calibration(camera=camera, per_view_rms_px=per_view,
                       rms_px=float(rms), views=tuple(used), missing=tuple(missing),
                       focal_sigma_px=(float(sigma[0]), float(sigma[1])))


def calibrate_images(
    images: Iterable[tuple[str, np.ndarray]], board: tuple[int, int], square_mm: float
) -> Calibration:
    """:func:`find_board` on each photo, then :func:`calibrate`.

    Parameters
    ----------
    images : iterable of (str, ndarray)
        (name, RGB image of shape (H, W, 3)); consumed one at a time, so a generator that
        decodes each photo when asked keeps one photo in memory.
    board, square_mm
        As for :func:`calibrate`.

    Raises
    ------
    InputError
        Photos of different sizes (naming the first two), or as :func:`calibrate`.
    """
    board = _check_board(board)
    names: list[str] = []
    corner_sets: list[np.ndarray | None] = []
    size: tuple[int, int] | None = None
    for name, image in images:
        shape = np.shape(image)
        this = (int(shape[1]), int(shape[0])) if len(shape) >= 2 else (0, 0)
        if size is None:
            size = this
        elif this != size:
            raise InputError(f"{name} is {this[0]}x{this[1]} px but {names[0]} is {size[0]}x{size[1]}: "
                             "calibrate photos of one camera at one size")
        names.append(name)
        corner_sets.append(find_board(image, board))
    if size is None:
        raise InputError("no photos given")
    return calibrate(corner_sets, board, square_mm, size, names=names)

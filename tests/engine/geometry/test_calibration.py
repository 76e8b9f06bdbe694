"""Chessboard calibration: OpenCV's real photos against OpenCV's published result for them, and
renders through a known camera with known lens distortion.

The real photos and the published result (``left_intrinsics.yml``, written by OpenCV's
calibration sample from the same 13 photos) come with Debian's opencv-doc package, which
scripts/setup installs; without it these tests fail, saying so.
"""

from __future__ import annotations

import gzip
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore.camera import CameraModel, undistort_points
from prismcore.errors import InputError
from prismcore.geometry.calibration import MIN_VIEWS, board_points, calibrate, calibrate_images, find_board
from prismcore.io.images import load_image

OPENCV_DATA = Path("/usr/share/doc/opencv-doc/examples/data")
LEFT = [f"left{i:02d}.jpg" for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14)]  # no left10
BOARD = (9, 6)


def opencv_photos(tmp_dir: Path) -> Path:
    """The folder holding left01.jpg ...: opencv-doc's own, or a decompressed copy of it."""
    if all((OPENCV_DATA / name).is_file() for name in LEFT):
        return OPENCV_DATA
    if all((OPENCV_DATA / f"{name}.gz").is_file() for name in LEFT):
        for name in [*LEFT, "left_intrinsics.yml"]:
            src = OPENCV_DATA / f"{name}.gz"
            if not src.is_file():
                continue
            with gzip.open(src) as fin, (tmp_dir / name).open("wb") as fout:
                shutil.copyfileobj(fin, fout)
        return tmp_dir
    pytest.fail(f"OpenCV's calibration photos ({OPENCV_DATA}/left01.jpg ...) are missing: install "
                "Debian's opencv-doc package (scripts/setup does)")


@pytest.fixture(scope="module")
def photo_dir(tmp_path_factory) -> Path:
    return opencv_photos(tmp_path_factory.mktemp("opencv-data"))


@pytest.fixture(scope="module")
def published(photo_dir) -> dict:
    """OpenCV's calibration sample's result for the same photos, read with OpenCV's own reader."""
    path = photo_dir / "left_intrinsics.yml"
    if not path.is_file():
        pytest.fail(f"{path} is missing: opencv-doc ships it with the photos")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    out = {"K": fs.getNode("camera_matrix").mat(),
           "dist": fs.getNode("distortion_coefficients").mat().ravel(),
           "rms": fs.getNode("avg_reprojection_error").real(),
           "nframes": int(fs.getNode("nframes").real()),
           "per_view": fs.getNode("per_view_reprojection_errors").mat().ravel()}
    fs.release()
    return out


@pytest.fixture(scope="module")
def real_calibration(photo_dir):
    return calibrate_images(((name, load_image(photo_dir / name)) for name in LEFT), BOARD, 25.0)


def test_real_photos_calibrate(real_calibration, published):
    cal = real_calibration
    cam = cal.camera
    assert cal.views == tuple(LEFT) and cal.missing == () and cal.views_used == published["nframes"]
    assert cal.rms_px < 0.25  # published: 0.39, lifted by left02 (below)
    assert cam.rms_px == cal.rms_px
    assert 530 < cam.fx < 540 and 530 < cam.fy < 540 and abs(cam.fx - cam.fy) < 1.0
    # Against the published result: the principal point within a few px, the focal length within
    # 0.6 % (the published one is pulled up by left02's misplaced corners, see the next test).
    K = published["K"]
    assert cam.fx == pytest.approx(K[0, 0], rel=0.006) and cam.fy == pytest.approx(K[1, 1], rel=0.006)
    assert abs(cam.cx - K[0, 2]) < 3 and abs(cam.cy - K[1, 2]) < 3
    assert cam.dist[0] == pytest.approx(published["dist"][0], abs=0.03)
    assert cal.per_view_rms_px.shape == (13,) and cal.per_view_rms_px.max() < 0.3
    assert published["per_view"][1] > 1.0  # left02 in the published run
    assert cal.focal_sigma_px[0] < 1.0 and cal.focal_sigma_px[1] < 1.0


def _corners_as_the_sample_finds_them(gray: np.ndarray) -> np.ndarray:
    """OpenCV's calibration sample (samples/cpp/calibration.cpp): classic detector, 11 px window."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_FAST_CHECK | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, BOARD, flags=flags)
    assert found
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 1e-4)
    return cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria).reshape(-1, 2)


def test_sample_corners_reproduce_the_published_result(photo_dir, published):
    """`calibrate` given the corners OpenCV's sample finds lands on the sample's published result
    (which also fixed fx = fy), so the fit is right and the difference above is the corners'."""
    sets = [_corners_as_the_sample_finds_them(cv2.imread(str(photo_dir / n), cv2.IMREAD_GRAYSCALE))
            for n in LEFT]
    cal = calibrate(sets, BOARD, 25.0, (640, 480), names=LEFT)
    K = published["K"]
    for ours, theirs in ((cal.camera.fx, K[0, 0]), (cal.camera.fy, K[1, 1]),
                         (cal.camera.cx, K[0, 2]), (cal.camera.cy, K[1, 2])):
        assert ours == pytest.approx(theirs, abs=0.5)
    assert cal.rms_px == pytest.approx(published["rms"], abs=0.03)
    np.testing.assert_allclose(cal.per_view_rms_px, published["per_view"], atol=0.1)
    # The distortion the two models apply over the whole photo: within 0.15 px RMS, 0.5 px at the
    # photo's far corners, which no board covers (k2, k3 are loosely determined there).
    u, v = np.meshgrid(np.linspace(0, 639, 17), np.linspace(0, 479, 13))
    rays = np.column_stack([(u.ravel() - K[0, 2]) / K[0, 0], (v.ravel() - K[1, 2]) / K[1, 1],
                            np.ones(u.size)])
    zero = np.zeros(3)
    theirs, _ = cv2.projectPoints(rays, zero, zero, K, published["dist"])
    ours, _ = cv2.projectPoints(rays, zero, zero, K, cal.camera.distortion())
    gap = np.linalg.norm((ours - theirs).reshape(-1, 2), axis=1)
    assert np.sqrt(np.mean(gap**2)) < 0.15 and gap.max() < 0.5
    # left02: the sample's 11 px window (its squares are 22 px) pulls corners onto the board's
    # edge; find_board's corners there are the ones the model fits.
    left02 = load_image(photo_dir / "left02.jpg")
    ours02 = find_board(left02, BOARD).astype(np.float64)
    theirs02 = sets[1]
    if np.linalg.norm(ours02[0] - theirs02[0]) > np.linalg.norm(ours02[0] - theirs02[-1]):
        ours02 = ours02[::-1]
    assert np.linalg.norm(ours02 - theirs02, axis=1).max() > 3.0
    assert cal.per_view_rms_px[1] > 1.0


# --------------------------------------------------------------------------------------------
# renders through a known camera

SIZE = (800, 600)
TRUE_K = np.array([[700.0, 0.0, 403.3], [0.0, 700.0, 296.8], [0.0, 0.0, 1.0]])
SQUARE = 25.0
SUPERSAMPLE = 8


def _project(points_xy: np.ndarray, rvec, tvec, K, dist) -> np.ndarray:
    p3 = np.column_stack([points_xy, np.zeros(len(points_xy))]).astype(np.float64)
    img, _ = cv2.projectPoints(p3, rvec, tvec, K, dist)
    return img.reshape(-1, 2)


def render_board(K, dist, rvec, tvec, *, seed: int, noise: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """A 10x7-square board (9x6 inner corners) photographed through (K, dist): RGB uint8 image,
    and the true image positions of the inner corners, (54, 2) px.

    Each square's outline is sampled densely and projected with OpenCV's forward distortion, so
    straight edges become the right curves; polygons are filled at 8x resolution and averaged
    down (area coverage), then sensor noise is added.
    """
    cols, rows = BOARD
    s = SUPERSAMPLE
    hi = np.full((SIZE[1] * s, SIZE[0] * s), 90, np.uint8)  # the table

    def outline(x0, y0, x1, y1):
        corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
        t = np.linspace(0.0, 1.0, 32, endpoint=False)[:, None]
        ends = zip(corners, np.roll(corners, -1, axis=0), strict=True)
        edge = np.vstack([a + t * (b - a) for a, b in ends])
        px = _project(edge, rvec, tvec, K, dist)
        return np.round(((px + 0.5) * s - 0.5) * 16).astype(np.int32)  # pixel centres; 4 fraction bits

    white = (-1.8 * SQUARE, cols * SQUARE + 0.8 * SQUARE, rows * SQUARE + 0.8 * SQUARE)  # paper
    cv2.fillPoly(hi, [outline(white[0], white[0], white[1], white[2])], 230, shift=4)
    black = [outline(i * SQUARE, j * SQUARE, (i + 1) * SQUARE, (j + 1) * SQUARE)
             for j in range(-1, rows) for i in range(-1, cols) if (i + j) % 2 == 0]
    cv2.fillPoly(hi, black, 25, shift=4)
    lo = cv2.resize(hi, SIZE, interpolation=cv2.INTER_AREA).astype(np.float64)
    lo += np.random.default_rng(seed).normal(0.0, noise, lo.shape)
    gray = np.clip(np.round(lo), 0, 255).astype(np.uint8)
    truth = _project(board_points(BOARD, SQUARE)[:, :2], rvec, tvec, K, dist)
    return np.repeat(gray[..., None], 3, axis=2), truth


def board_poses(K, dist, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """12 poses: the board centred on a 3x3 grid over the frame and three times in the middle,
    tilted up to 30 degrees each way, whole board (with its white margin) in the frame."""
    rng = np.random.default_rng(seed)
    cols, rows = BOARD
    edge = np.array([[-1, -1], [cols, -1], [cols, rows], [-1, rows]], dtype=np.float64) * SQUARE
    centre = np.array([(cols - 1) * SQUARE / 2, (rows - 1) * SQUARE / 2, 0.0])
    targets = [(x, y) for y in (0.28, 0.5, 0.72) for x in (0.27, 0.5, 0.73)] + [(0.5, 0.5)] * 3
    poses = []
    for tx, ty in targets:
        while True:
            rvec = np.deg2rad([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-15, 15)])
            R, _ = cv2.Rodrigues(rvec)
            aim = (tx * SIZE[0] + rng.uniform(-20, 20), ty * SIZE[1] + rng.uniform(-20, 20), 1.0)
            ray = np.linalg.solve(K, aim)
            tvec = ray * rng.uniform(300, 420) - R @ centre
            px = _project(edge, rvec, tvec, K, dist)
            if px.min() > 4 and px[:, 0].max() < SIZE[0] - 5 and px[:, 1].max() < SIZE[1] - 5:
                poses.append((rvec, tvec))
                break
    return poses


@pytest.fixture(scope="module", params=[-0.12, 0.08], ids=["barrel", "pincushion"])
def rendered(request):
    k1 = request.param
    dist = np.array([k1, 0.0, 0.0, 0.0, 0.0])
    poses = board_poses(TRUE_K, dist)
    views = [render_board(TRUE_K, dist, r, t, seed=i) for i, (r, t) in enumerate(poses)]
    cal = calibrate_images(((f"view {i}", img) for i, (img, _) in enumerate(views)), BOARD, SQUARE)
    return {"k1": k1, "dist": dist, "poses": poses, "views": views, "cal": cal}


def _same_start(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The board read from the other end (a 180 degree turn of its numbering) put back in order."""
    flip = np.linalg.norm(found[0] - truth[0]) > np.linalg.norm(found[0] - truth[-1])
    return found[::-1] if flip else found


def test_find_board_corners_on_renders(rendered):
    errors = []
    for img, truth in rendered["views"]:
        found = find_board(img, BOARD)
        assert found is not None and found.shape == (54, 2) and found.dtype == np.float32
        errors.append(np.linalg.norm(_same_start(found.astype(np.float64), truth) - truth, axis=1))
    errors = np.concatenate(errors)
    assert np.sqrt(np.mean(errors**2)) < 0.1 and errors.max() < 0.3


def test_rendered_camera_is_recovered(rendered):
    cal = rendered["cal"]
    cam = cal.camera
    assert cal.views_used == 12 and cal.missing == ()
    assert cal.rms_px < 0.1 and cal.per_view_rms_px.max() < 0.1
    assert (cam.image_width, cam.image_height) == SIZE
    for value, sigma in zip((cam.fx, cam.fy), cal.focal_sigma_px, strict=True):
        assert abs(value - 700.0) < 1.0 and abs(value - 700.0) < 4 * sigma
    assert abs(cam.cx - 403.3) < 1.0 and abs(cam.cy - 296.8) < 1.0
    assert cam.dist[0] == pytest.approx(rendered["k1"], abs=0.005)
    assert abs(cam.dist[2]) < 1e-3 and abs(cam.dist[3]) < 1e-3  # no tangential distortion


def test_undistorted_corners_land_on_the_pinhole_projection(rendered):
    true_cam = CameraModel(fx=700, fy=700, cx=403.3, cy=296.8, dist=list(rendered["dist"]),
                           image_width=SIZE[0], image_height=SIZE[1])
    fitted, exact = [], []
    for (rvec, tvec), (_, distorted) in zip(rendered["poses"], rendered["views"], strict=True):
        pinhole = _project(board_points(BOARD, SQUARE)[:, :2], rvec, tvec, TRUE_K, np.zeros(5))
        fitted.append(np.linalg.norm(undistort_points(distorted, rendered["cal"].camera) - pinhole, axis=1))
        exact.append(np.linalg.norm(undistort_points(distorted, true_cam) - pinhole, axis=1))
    fitted, exact = np.concatenate(fitted), np.concatenate(exact)
    assert exact.max() < 0.01  # undistort_points inverts the distortion it is given
    assert np.sqrt(np.mean(fitted**2)) < 0.06 and fitted.max() < 0.25  # and the fitted one is right


def test_large_photo_detected_downscaled_and_refined_at_full_size():
    scale = 3  # 2400x1800: detected on a copy under 2000 px, refined on the photo itself
    dist = np.array([-0.12, 0.0, 0.0, 0.0, 0.0])
    rvec, tvec = board_poses(TRUE_K, dist)[4]
    img, truth = render_board(TRUE_K, dist, rvec, tvec, seed=0)
    big = cv2.resize(img, (SIZE[0] * scale, SIZE[1] * scale), interpolation=cv2.INTER_CUBIC)
    truth_big = (truth + 0.5) * scale - 0.5
    found = find_board(big, BOARD)
    assert found is not None
    err = np.linalg.norm(_same_start(found.astype(np.float64), truth_big) - truth_big, axis=1)
    assert err.mean() < 0.2 and err.max() < 0.5


# --------------------------------------------------------------------------------------------
# refusals


def _blank(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.integers(0, 256, (SIZE[1], SIZE[0], 3), dtype=np.uint8), (0, 0), 3)


@pytest.mark.parametrize("boards", [0, 1, 2])
def test_too_few_boards_refused_naming_the_photos_without_one(boards):
    dist = np.zeros(5)
    poses = board_poses(TRUE_K, dist)
    photos = [(f"board{i}.png", render_board(TRUE_K, dist, *poses[i], seed=i)[0]) for i in range(boards)]
    photos += [("empty-a.png", _blank(1)), ("empty-b.png", _blank(2))]
    with pytest.raises(InputError) as info:
        calibrate_images(photos, BOARD, SQUARE)
    msg = str(info.value)
    assert f"found in {boards} of {boards + 2} photos" in msg and f"at least {MIN_VIEWS}" in msg
    assert "empty-a.png, empty-b.png" in msg and "board0" not in msg and "\n" not in msg


def test_photos_of_different_sizes_refused():
    dist = np.zeros(5)
    img, _ = render_board(TRUE_K, dist, *board_poses(TRUE_K, dist)[0], seed=0)
    with pytest.raises(InputError, match=r"b\.png is 400x300 px but a\.png is 800x600"):
        calibrate_images([("a.png", img), ("b.png", img[::2, ::2])], BOARD, SQUARE)


def _synthetic_corners(rvecs, tvecs, dist, noise=0.05, seed=0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    pts = board_points(BOARD, SQUARE)[:, :2]
    return [_project(pts, r, t, TRUE_K, dist) + rng.normal(0, noise, (54, 2))
            for r, t in zip(rvecs, tvecs, strict=True)]


@pytest.mark.parametrize(
    "rvecs",
    [[np.zeros(3)] * 4,  # square-on: focal length and distance interchangeable
     [np.array([0.3, 0.0, 0.0])] * 4],  # one tilt for all
    ids=["square-on", "one-tilt"],
)
def test_undetermined_focal_length_refused(rvecs):
    tvecs = [np.array([-100.0 + 20 * i, -60.0 + 10 * i, 350.0 + 30 * i]) for i in range(len(rvecs))]
    with pytest.raises(InputError, match=r"focal length \d+\.\d px undetermined"):
        calibrate(_synthetic_corners(rvecs, tvecs, np.array([-0.1, 0, 0, 0, 0.0])), BOARD, SQUARE, SIZE)


def test_distortion_folding_inside_the_photo_refused():
    """Boards only in the middle of the frame: the fitted k2, k3 extrapolate to the photo's
    corners, where the model turns back on itself (no undistorted position for those pixels)."""
    rng = np.random.default_rng(0)
    rvecs, tvecs = [], []
    for _ in range(8):
        rvecs.append(np.deg2rad([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-15, 15)]))
        shift = (rng.uniform(-15, 15), rng.uniform(-15, 15), rng.uniform(500, 600))
        tvecs.append(np.array([-100.0, -62.5, 0.0]) + shift)
    corners = _synthetic_corners(rvecs, tvecs, np.array([-0.3, 0, 0, 0, 0.0]), seed=1)
    with pytest.raises(InputError, match="folds the image back"):
        calibrate(corners, BOARD, SQUARE, SIZE)


@pytest.mark.parametrize(
    ("corners", "board", "square", "size", "needle"),
    [
        ("short", BOARD, SQUARE, SIZE, r"shape \(20, 2\)"),
        ("outside", BOARD, SQUARE, SIZE, "outside the 800x600"),
        ("ok", (2, 6), SQUARE, SIZE, r"board \(2, 6\)"),
        ("ok", (9.5, 6), SQUARE, SIZE, r"board \(9.5, 6\)"),
        ("ok", BOARD, -25.0, SIZE, "square size -25.0"),
        ("ok", BOARD, float("nan"), SIZE, "square size nan"),
        ("ok", BOARD, SQUARE, (800,), r"image size \(800,\)"),
    ],
)
def test_bad_arguments_refused(corners, board, square, size, needle):
    dist = np.zeros(5)
    poses = board_poses(TRUE_K, dist)[:4]
    sets = _synthetic_corners([p[0] for p in poses], [p[1] for p in poses], dist)
    if corners == "short":
        sets[2] = sets[2][:20]
    elif corners == "outside":
        sets[1] = sets[1] + (500.0, 0.0)
    with pytest.raises(InputError, match=needle):
        calibrate(sets, board, square, size)


def test_find_board_refuses_a_non_rgb_array():
    with pytest.raises(InputError, match=r"shape \(600, 800\)"):
        find_board(np.zeros((600, 800), np.uint8), BOARD)
    assert find_board(_blank(0), BOARD) is None

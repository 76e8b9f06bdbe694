"""Station scenes: a textured table with a ChArUco board on it, a fixed camera looking down at
30-60 degrees from 0.4-1.2 m with lens distortion, and a box of known size resting on the board
at a random position and yaw, lit by one light that casts its shadow.

Each scene gives the plate (the empty table, as calibrated) and the photo (the part, the light
changed up to +-20 %, the camera nudged a few pixels for some), JPEG-compressed, with the truth:
the box's dimensions, position and yaw in the board's frame, and the camera. The board's frame
is OpenCV's ChArUco frame: x along its width, y along its height, z into the table (a point
h mm above the table has z = -h).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import cv2
import numpy as np

from prismcore.station.board import BoardSpec, board_image

__all__ = [
    "StationBox",
    "StationScene",
    "StationSetup",
    "calibration_views",
    "station_board",
    "station_scene",
    "station_setup",
]

_SS = 2  # supersampling of the ideal render
_TEX_PX_PER_MM = 1.0


def station_board() -> BoardSpec:
    """The benchmark's board: a 9x6 ChArUco of 40 mm squares (360 x 240 mm, an A3 print)."""
    return BoardSpec(
        type="charuco", dictionary="DICT_5X5_100", squares_x=9, squares_y=6, square_mm=40.0, marker_mm=30.0
    )


@dataclass(frozen=True)
class StationSetup:
    """A camera fixed above a table: intrinsics, distortion and its pose (board -> camera)."""

    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    image_size: tuple[int, int]
    board: BoardSpec
    table: np.ndarray  # (Ht, Wt, 3) uint8 table texture, _TEX_PX_PER_MM, centred on the board
    table_origin_mm: tuple[float, float]  # board-frame (x, y) of the texture's pixel (0, 0)
    distance_mm: float
    elevation_deg: float


@dataclass(frozen=True)
class StationBox:
    """The truth: a box resting on the table. length along its own x, width along y, height up."""

    length_mm: float
    width_mm: float
    height_mm: float
    x_mm: float  # centre of the footprint, board frame
    y_mm: float
    yaw_deg: float
    color: tuple[float, float, float]

    @property
    def dimensions(self) -> dict[str, float]:
        """As the station reports them: height, then width >= depth (the footprint's sides)."""
        return {
            "width": max(self.length_mm, self.width_mm),
            "height": self.height_mm,
            "depth": min(self.length_mm, self.width_mm),
        }

    def corners(self) -> np.ndarray:
        """(8, 3) board-frame corners: the footprint (z = 0) then the top (z = -height)."""
        c, s = np.cos(np.radians(self.yaw_deg)), np.sin(np.radians(self.yaw_deg))
        hl, hw = self.length_mm / 2, self.width_mm / 2
        local = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]])
        xy = local @ np.array([[c, s], [-s, c]]) + (self.x_mm, self.y_mm)
        bottom = np.column_stack([xy, np.zeros(4)])
        top = np.column_stack([xy, np.full(4, -self.height_mm)])
        return np.vstack([bottom, top])


@dataclass(frozen=True)
class StationScene:
    plate: np.ndarray  # (H, W, 3) uint8, JPEG round-tripped
    photo: np.ndarray
    box: StationBox | None
    setup: StationSetup
    gain: float  # the photo's light over the plate's
    nudge_px: float  # how far the camera was turned since the plate, px at the image centre
    near_table_colour: bool
    extra_boxes: list[StationBox] = field(default_factory=list)


def _look_at(centre: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = target - centre
    z /= np.linalg.norm(z)
    down = np.array([0.0, 0.0, 1.0])  # into the table: the image's "down" is towards the camera
    y = down - (down @ z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    R = np.vstack([x, y, z])
    return R, -R @ centre


def _table_texture(rng: np.random.Generator, size_mm: float) -> np.ndarray:
    n = int(size_mm * _TEX_PX_PER_MM)
    base = rng.uniform(70, 200, 3)
    low = cv2.resize(rng.normal(0, 1, (8, 8, 3)).astype(np.float32), (n, n), interpolation=cv2.INTER_CUBIC)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (n, n)).astype(np.float32), (0, 0), 1.5)
    # wood-like streaks along one axis
    streak = cv2.resize(
        rng.normal(0, 1, (1, n // 6)).astype(np.float32), (n, n), interpolation=cv2.INTER_LINEAR
    )
    tex = base + 10 * low + 12 * grain[..., None] * rng.uniform(0.5, 1.5) + 10 * streak[..., None]
    return np.clip(tex, 0, 255).astype(np.uint8)


def station_setup(
    seed: int,
    *,
    image_size: tuple[int, int] = (1280, 1024),
    distance_mm: float | None = None,
    elevation_deg: float | None = None,
    board: BoardSpec | None = None,
) -> StationSetup:
    rng = np.random.default_rng([seed, 7177])
    board = station_board() if board is None else board
    w, h = image_size
    d = float(distance_mm if distance_mm is not None else rng.uniform(400, 1200))
    # A station's lens frames its work area: the board spans 50-75 % of the photo's width.
    f = rng.uniform(0.5, 0.75) * w * d / board.size_mm[0]
    K = np.array(
        [[f, 0, w / 2 - 0.5 + rng.uniform(-15, 15)], [0, f, h / 2 - 0.5 + rng.uniform(-15, 15)], [0, 0, 1]]
    )
    dist = np.array([rng.uniform(-0.2, 0.05), rng.uniform(-0.05, 0.1), 0.0, 0.0, 0.0])
    el = float(elevation_deg if elevation_deg is not None else rng.uniform(30, 60))
    az = rng.uniform(0, 2 * np.pi)
    bw, bh = board.size_mm
    target = np.array([bw / 2 + rng.uniform(-20, 20), bh / 2 + rng.uniform(-20, 20), 0.0])
    centre = target + d * np.array(
        [np.cos(np.radians(el)) * np.cos(az), np.cos(np.radians(el)) * np.sin(az), -np.sin(np.radians(el))]
    )
    R, t = _look_at(centre, target)
    size = 2400.0
    table = _table_texture(rng, size)
    origin = (bw / 2 - size / 2, bh / 2 - size / 2)
    return StationSetup(
        K=K,
        dist=dist,
        R=R,
        t=t,
        image_size=image_size,
        board=board,
        table=table,
        table_origin_mm=origin,
        distance_mm=d,
        elevation_deg=el,
    )


def _project(
    setup: StationSetup,
    X: np.ndarray,
    R: np.ndarray | None = None,
    t: np.ndarray | None = None,
    scale: float = 1.0,
) -> np.ndarray:
    """Ideal pinhole projection (no distortion) at `scale` x the image."""
    R = setup.R if R is None else R
    t = setup.t if t is None else t
    cam = X @ R.T + t
    uv = cam[:, :2] / cam[:, 2:3]
    K = setup.K
    px = np.column_stack([K[0, 0] * uv[:, 0] + K[0, 2], K[1, 1] * uv[:, 1] + K[1, 2]])
    return (px + 0.5) * scale - 0.5


def _plane_homography(setup: StationSetup, R: np.ndarray, t: np.ndarray, scale: float) -> np.ndarray:
    """Board-frame (x, y) mm -> ideal image px at `scale`."""
    S = np.array([[scale, 0, (scale - 1) / 2], [0, scale, (scale - 1) / 2], [0, 0, 1]])
    return cast("np.ndarray", S @ setup.K @ np.column_stack([R[:, 0], R[:, 1], t]))


def _distort_map(setup: StationSetup) -> tuple[np.ndarray, np.ndarray]:
    """For every pixel of the distorted photo, where it lies in the ideal (pinhole) render."""
    w, h = setup.image_size
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1).reshape(-1, 1, 2)
    ideal = cv2.undistortPoints(
        pts,
        setup.K,
        setup.dist,
        None,
        None,
        setup.K,
        (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-6),
    ).reshape(h, w, 2)
    ideal = (ideal + 0.5) * _SS - 0.5
    return ideal[..., 0].astype(np.float32), ideal[..., 1].astype(np.float32)


# The last lens's map, keyed on what it is made of: keyed on id(setup), a setup freed and another
# made at the same address (the next seed's) was rendered through the previous camera's lens.
_MAPS: dict[tuple[bytes, bytes, tuple[int, ...]], tuple[np.ndarray, np.ndarray]] = {}


def _render(
    setup: StationSetup,
    R: np.ndarray,
    t: np.ndarray,
    boxes: list[StationBox],
    light: np.ndarray,
    gain: float,
    rng: np.random.Generator,
    *,
    shadow: float,
) -> np.ndarray:
    w, h = setup.image_size
    W, H = w * _SS, h * _SS
    Hp = _plane_homography(setup, R, t, _SS)
    ox, oy = setup.table_origin_mm
    T = np.array([[1 / _TEX_PX_PER_MM, 0, ox], [0, 1 / _TEX_PX_PER_MM, oy], [0, 0, 1]])
    img: np.ndarray = cv2.warpPerspective(
        setup.table, Hp @ T, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT
    ).astype(np.float32)
    # The board, printed on matte white paper.
    ppm = 4.0
    art = board_image(setup.board, ppm).astype(np.float32)
    paper = np.where(art > 127, 230.0, 38.0)  # matte print: its black is not black
    B = np.array([[1 / ppm, 0, 0], [0, 1 / ppm, 0], [0, 0, 1]])
    warped = cv2.warpPerspective(np.dstack([paper] * 3), Hp @ B, (W, H), flags=cv2.INTER_AREA)
    cover = cv2.warpPerspective(np.ones(art.shape, np.float32), Hp @ B, (W, H), flags=cv2.INTER_LINEAR)
    img = img * (1 - cover[..., None]) + warped * cover[..., None]
    # Shadows on the table: each box's outline cast along the light onto z = 0.
    centre = -R.T @ t
    for box in boxes:
        X = box.corners()
        s = -X[:, 2] / light[2]
        ground = X + s[:, None] * light  # light points from the lamp towards the table (z > 0)
        poly = _project(setup, ground, R, t, _SS)
        hull = cv2.convexHull(poly.astype(np.float32))
        mask: np.ndarray = np.zeros((H, W), np.float32)
        cv2.fillConvexPoly(mask, np.round(hull * 16).astype(np.int32), 1.0, lineType=cv2.LINE_AA, shift=4)
        mask = cv2.GaussianBlur(mask, (0, 0), 3.0)
        img *= (1 - shadow * mask)[..., None]
    # The boxes, far ones first.
    for box in sorted(boxes, key=lambda b: -np.linalg.norm(np.array([b.x_mm, b.y_mm, 0]) - centre)):
        X = box.corners()
        faces = {
            "bottom": [0, 1, 2, 3],
            "top": [4, 5, 6, 7],
            "s0": [0, 1, 5, 4],
            "s1": [1, 2, 6, 5],
            "s2": [2, 3, 7, 6],
            "s3": [3, 0, 4, 7],
        }
        mid = X.mean(axis=0)
        for idx in faces.values():
            Fc = X[idx]
            n = np.cross(Fc[1] - Fc[0], Fc[2] - Fc[0])
            n /= np.linalg.norm(n)
            if n @ (Fc.mean(axis=0) - mid) < 0:
                n = -n
            if n @ (centre - Fc.mean(axis=0)) <= 0:
                continue
            shade = 0.45 + 0.65 * max(0.0, float(-n @ light))
            colour = np.clip(np.asarray(box.color) * shade, 0, 255)
            _fill_exact(img, _project(setup, Fc, R, t, _SS), colour)
    img *= gain
    img = cv2.GaussianBlur(img, (0, 0), 0.6 * _SS)
    key = (np.asarray(setup.K, np.float64).tobytes(), np.asarray(setup.dist, np.float64).tobytes(),
           tuple(setup.image_size))
    if key not in _MAPS:
        _MAPS.clear()
        _MAPS[key] = _distort_map(setup)
    mx, my = _MAPS[key]
    out: np.ndarray = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    out = out + rng.normal(0, 2.0, out.shape).astype(np.float32)
    return cast("np.ndarray", np.clip(out, 0, 255).astype(np.uint8))


def _fill_exact(img: np.ndarray, poly: np.ndarray, colour: np.ndarray) -> None:
    """Paint convex polygon `poly` (N, 2) px (x, y, pixel centres at integers) into `img` (H, W, 3)
    float32, each pixel by the share of it the polygon covers (from its centre's signed distance to
    the nearest side: exact along the sides). OpenCV's anti-aliased fill paints every pixel an edge
    touches, about half a pixel too far out on every side: a part drawn that way is measured long."""
    h, w = img.shape[:2]
    x0, y0 = np.maximum(np.floor(poly.min(axis=0)).astype(int) - 2, 0)
    x1, y1 = np.minimum(np.ceil(poly.max(axis=0)).astype(int) + 3, (w, h))
    if x1 <= x0 or y1 <= y0:
        return
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    area2 = float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))  # > 0: counter-clockwise in (x, y)
    inside = np.full(xs.shape, np.inf)
    for (ax, ay), (dx, dy) in zip(a, ab, strict=True):
        length = float(np.hypot(dx, dy))
        if length < 1e-9:
            continue
        d = (dx * (ys - ay) - dy * (xs - ax)) / length  # > 0 left of the side
        np.minimum(inside, d if area2 > 0 else -d, out=inside)
    cover = np.clip(inside + 0.5, 0.0, 1.0).astype(np.float32)[..., None]
    region = img[y0:y1, x0:x1]
    region *= 1 - cover
    region += cover * np.asarray(colour, np.float32)


# A JPEG's colour sampling: "420" halves the colour's resolution both ways (phones, most cameras'
# default), "444" keeps it whole (a machine-vision camera's setting).
_SAMPLING = {"420": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420, "444": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444}


def _jpeg(image: np.ndarray, quality: int, chroma: str = "420") -> np.ndarray:
    ok, data = cv2.imencode(
        ".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
        [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, _SAMPLING[chroma]],
    )
    assert ok
    decoded = cast("np.ndarray", cv2.imdecode(data, cv2.IMREAD_COLOR))  # None only for bad bytes
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)


def _random_box(
    rng: np.random.Generator, setup: StationSetup, near_colour: np.ndarray | None, max_size_mm: float
) -> StationBox:
    bw, bh = setup.board.size_mm
    size = float(np.exp(rng.uniform(np.log(20), np.log(max_size_mm))))
    # every side 20 mm at least: the parts a station is for
    dims = sorted([size, max(20.0, size * rng.uniform(0.35, 1.0)), max(20.0, size * rng.uniform(0.25, 1.0))],
                  reverse=True)
    rng.shuffle(dims)
    length, width, height = dims
    reach = max(length, width) / 2
    x = rng.uniform(min(reach, bw / 2), max(bw - reach, bw / 2))
    y = rng.uniform(min(reach, bh / 2), max(bh - reach, bh / 2))
    if near_colour is not None:
        colour = np.clip(near_colour + rng.uniform(-10, 10, 3), 0, 255)
    else:
        colour = rng.uniform(20, 235, 3)
    rgb = (float(colour[0]), float(colour[1]), float(colour[2]))
    return StationBox(length, width, height, x, y, float(rng.uniform(0, 180)), rgb)


def _in_view(setup: StationSetup, box: StationBox, margin: float) -> bool:
    pts = cv2.projectPoints(box.corners(), cv2.Rodrigues(setup.R)[0], setup.t, setup.K, setup.dist)[
        0
    ].reshape(-1, 2)
    cam = box.corners() @ setup.R.T + setup.t
    w, h = setup.image_size
    return bool(np.all(cam[:, 2] > 50) and np.all(pts > margin) and np.all(pts < (w - margin, h - margin)))


def station_scene(
    seed: int,
    setup: StationSetup | None = None,
    *,
    parts: int = 1,
    nudge: bool | None = None,
    near_table_colour: bool | None = None,
    max_size_mm: float = 400.0,
    quality: int = 85,
    chroma: str = "420",
    inside_board: bool = False,
    box: StationBox | None = None,
) -> StationScene:
    """One station photo and its plate, with the truth (see the module's docstring).

    parts : 0 for an empty support, 2 for two parts (refusal tests).
    nudge : camera turned 1-3 px since the plate (default: every other seed).
    near_table_colour : the part's colour within 10 RGB levels of the table's mean (default: 10 %).
    inside_board : the part's footprint on the board, 15 mm from its edges (hand-held photos).
    box : the one part, placed as given (a reference part's placements); it must be in view.
    quality, chroma : the JPEG's quality and colour sampling ("420" or "444") of the plate and photo.
    """
    rng = np.random.default_rng([seed, 31])
    setup = setup if setup is not None else station_setup(seed)
    nudge = bool(seed % 2) if nudge is None else nudge
    near = bool(rng.uniform() < 0.1) if near_table_colour is None else near_table_colour
    table_mean = setup.table.reshape(-1, 3).mean(axis=0)
    boxes: list[StationBox] = []
    if box is not None:
        if not _in_view(setup, box, 40):
            raise ValueError(f"the box at ({box.x_mm:g}, {box.y_mm:g}) mm is not in view")
        boxes, parts = [box], 0
    for _ in range(parts):
        for _attempt in range(200):
            box = _random_box(rng, setup, table_mean if near else None, max_size_mm)
            far_apart = all(
                np.hypot(box.x_mm - b.x_mm, box.y_mm - b.y_mm)
                > 0.6 * (max(box.length_mm, box.width_mm) + max(b.length_mm, b.width_mm))
                for b in boxes
            )
            bw, bh = setup.board.size_mm
            foot = box.corners()[:4, :2]
            on_board = bool(np.all(foot > 15) and np.all(foot < (bw - 15, bh - 15)))
            if _in_view(setup, box, 40) and far_apart and (on_board or not inside_board):
                boxes.append(box)
                break
            max_size_mm = max(25.0, max_size_mm * 0.97)
        else:
            raise RuntimeError(f"seed {seed}: no box fits in view")
    az = rng.uniform(0, 2 * np.pi)
    tilt = np.radians(rng.uniform(15, 45))
    light = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    plate = _jpeg(_render(setup, setup.R, setup.t, [], light, 1.0, rng, shadow=0.0), quality, chroma)
    gain = float(rng.uniform(0.8, 1.2))
    R, t = setup.R, setup.t
    nudge_px = 0.0
    if nudge:
        f = setup.K[0, 0]
        nudge_px = float(rng.uniform(1.0, 3.0))
        angle = nudge_px / f
        axis = rng.normal(size=3)
        axis[2] *= 0.2
        axis *= angle / np.linalg.norm(axis)
        dR = cv2.Rodrigues(axis)[0]
        R, t = dR @ setup.R, dR @ setup.t
    photo = _jpeg(
        _render(setup, R, t, boxes, light, gain, rng, shadow=float(rng.uniform(0.3, 0.55))), quality, chroma
    )
    return StationScene(
        plate=plate,
        photo=photo,
        box=boxes[0] if boxes else None,
        setup=setup,
        gain=gain,
        nudge_px=nudge_px,
        near_table_colour=near,
        extra_boxes=boxes[1:],
    )


def calibration_views(setup: StationSetup, n: int, seed: int) -> list[np.ndarray]:
    """Photos of the board alone in `n` poses by the same camera (for the intrinsics), JPEG q90."""
    rng = np.random.default_rng([seed, 991])
    light = np.array([0.3, 0.2, 0.93])
    out = []
    bw, bh = setup.board.size_mm
    for _ in range(n):
        el = rng.uniform(35, 70)
        az = rng.uniform(0, 2 * np.pi)
        d = rng.uniform(0.9, 1.3) * max(setup.K[0, 0] * bw / setup.image_size[0] * 1.4, 350)
        target = np.array([bw / 2, bh / 2, 0.0]) + rng.uniform(-30, 30, 3) * (1, 1, 0)
        centre = target + d * np.array(
            [
                np.cos(np.radians(el)) * np.cos(az),
                np.cos(np.radians(el)) * np.sin(az),
                -np.sin(np.radians(el)),
            ]
        )
        R, t = _look_at(centre, target)
        roll = cv2.Rodrigues(np.array([0, 0, rng.uniform(-0.4, 0.4)]))[0]
        R, t = roll @ R, roll @ t
        out.append(_jpeg(_render(setup, R, t, [], light, 1.0, rng, shadow=0.0), 90))
    return out

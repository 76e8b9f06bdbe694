"""What is in a scene, drawn at random from a seed and a `Settings`: the sheet and its board, the
table, the lights, the clutter, the part and its material, the camera. Pure description, no
rendering: `render.py` turns it into light.

Frames: the board's (x along its width, y along its height, z into the table; the table's top
is z = 0, heights above it negative z), millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from prismcore.station.board import PAPER_MM, BoardSpec, default_board

from .camera import LensCamera, look_at

__all__ = ["Clutter", "Light", "Part", "Scene", "Settings", "handheld_scene", "station_scenes"]

PART_MATERIALS = ("kraft", "glossy", "aluminium", "steel", "black", "white")
TABLES = ("wood", "laminate", "metal", "fabric", "printed")


@dataclass(frozen=True)
class Settings:
    """The ranges a set of scenes is drawn from. The development and report sets differ in them
    (and in seeds), so a figure on the report set is one the tuning never saw."""

    name: str
    image_size: tuple[int, int] = (1024, 768)
    spp: int = 8
    papers: tuple[str, ...] = ("A4", "A3")
    squares: tuple[tuple[int, int], ...] = ((7, 5), (9, 6))
    own_square_share: float = 0.0  # boards printed at another scale, their squares measured
    part_mm: tuple[float, float] = (15.0, 500.0)
    radius_mm: tuple[float, float] = (0.5, 3.0)
    materials: tuple[float, ...] = (1, 1, 1, 1, 1, 1)  # weights of PART_MATERIALS
    tables: tuple[float, ...] = (1, 1, 1, 1, 1)  # weights of TABLES
    lights: tuple[int, int] = (1, 3)
    window_share: float = 0.5
    clutter: tuple[int, int] = (0, 4)
    hand_shadow_share: float = 0.15
    over_edge_share: float = 0.2
    station_distance_mm: tuple[float, float] = (500.0, 1100.0)
    station_elevation_deg: tuple[float, float] = (35.0, 70.0)
    hand_distance_mm: tuple[float, float] = (280.0, 650.0)
    hand_elevation_deg: tuple[float, float] = (35.0, 75.0)
    hand_part_mm: tuple[float, float] = (15.0, 250.0)
    k1: tuple[float, float] = (-0.12, 0.04)
    jpeg_quality: tuple[int, int] = (80, 95)
    noise_electrons: tuple[float, float] = (1500.0, 8000.0)


DEVELOPMENT = Settings(name="development")
REPORT = Settings(
    name="report",
    spp=10,
    papers=("A4", "A3", "letter"),
    squares=((7, 5), (9, 6), (8, 6), (6, 4)),
    own_square_share=0.25,
    materials=(1.0, 1.2, 1.0, 0.8, 1.0, 1.0),
    tables=(1.2, 1.0, 0.8, 0.8, 1.0),
    lights=(1, 4),
    window_share=0.6,
    clutter=(1, 5),
    hand_shadow_share=0.2,
    over_edge_share=0.25,
    station_distance_mm=(450.0, 1200.0),
    station_elevation_deg=(32.0, 72.0),
    hand_distance_mm=(250.0, 700.0),
    hand_elevation_deg=(32.0, 78.0),
    k1=(-0.15, 0.06),
    jpeg_quality=(75, 95),
    noise_electrons=(1000.0, 9000.0),
)
SETS = {"development": DEVELOPMENT, "report": REPORT}


@dataclass(frozen=True)
class Part:
    """The truth: a box resting on the table. length along its own x, width along y, height up."""

    length_mm: float
    width_mm: float
    height_mm: float
    x_mm: float
    y_mm: float
    yaw_deg: float
    radius_mm: float
    material: str
    seed: int

    @property
    def dimensions(self) -> dict[str, float]:
        """As the station reports them: width >= depth (the footprint's sides), height."""
        return {
            "width": max(self.length_mm, self.width_mm),
            "height": self.height_mm,
            "depth": min(self.length_mm, self.width_mm),
        }

    def corners(self) -> np.ndarray:
        """(8, 3): the footprint (z = 0) then the top (z = -height), board frame."""
        c, s = np.cos(np.radians(self.yaw_deg)), np.sin(np.radians(self.yaw_deg))
        hl, hw = self.length_mm / 2, self.width_mm / 2
        local = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]])
        xy = local @ np.array([[c, s], [-s, c]]) + (self.x_mm, self.y_mm)
        return np.vstack(
            [np.column_stack([xy, np.zeros(4)]), np.column_stack([xy, np.full(4, -self.height_mm)])]
        )


@dataclass(frozen=True)
class Light:
    """kind: "area" (a rectangle facing down), "window" (a tall rectangle facing the table),
    "ambient" (a constant sky). centre (3,), size (w, h) mm, rgb radiance."""

    kind: str
    centre: tuple[float, float, float]
    size: tuple[float, float]
    rgb: tuple[float, float, float]
    facing: tuple[float, float, float] = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Clutter:
    """kind: "box", "mug", "ball", "cable", "ruler", "hand" (an occluder out of view)."""

    kind: str
    x_mm: float
    y_mm: float
    size: tuple[float, float, float]
    yaw_deg: float
    rgb: tuple[float, float, float]
    metal: bool = False
    path: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class Exposure:
    """A photo's own camera settings: auto exposure's bias, white balance's error per channel,
    JPEG quality, the sensor's full well (electrons: its shot noise)."""

    bias_ev: float
    white_balance_error: tuple[float, float, float]
    jpeg_quality: int
    full_well: float


def _v3(v: object) -> tuple[float, float, float]:
    a = np.asarray(v, float).ravel()
    return (float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True)
class Scene:
    settings: Settings
    seed: int
    board: BoardSpec  # what the user's board.json says (the square as printed or as measured)
    paper: str
    paper_mm: tuple[float, float]  # the sheet as laid (width, height)
    sheet_origin_mm: tuple[float, float]  # board-frame (x, y) of the sheet's top-left corner
    page_board_offset_mm: tuple[float, float]
    ink: float
    paper_white: float
    table: str
    table_seed: int
    table_extent_mm: tuple[float, float, float, float]  # x0, y0, x1, y1 of the table's top
    lights: tuple[Light, ...]
    clutter: tuple[Clutter, ...]
    camera: LensCamera
    part: Part | None
    exposure: Exposure
    extras: dict[str, object] = field(default_factory=dict)

    def with_part(self, part: Part | None, rng: np.random.Generator) -> Scene:
        """The same station (camera, light, table) with another part and the photo's own
        exposure, white balance and noise."""
        return replace(self, part=part, exposure=_exposure(self.settings, rng))


# The camera is chosen after the sheet (it frames the board): a scene is drawn with this first.
_UNSET = LensCamera(np.eye(3), np.zeros(5), np.eye(3), np.zeros(3), (1, 1))


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _kelvin_rgb(k: float) -> tuple[float, float, float]:
    # A few points of a blackbody's white-balanced colour, interpolated: enough for variety.
    ks = [2700, 3500, 4500, 5500, 6500, 8000]
    rgb = np.array(
        [
            [1.0, 0.66, 0.36],
            [1.0, 0.77, 0.54],
            [1.0, 0.87, 0.73],
            [1.0, 0.94, 0.88],
            [0.98, 0.98, 1.0],
            [0.85, 0.90, 1.0],
        ]
    )
    return _v3([np.interp(k, ks, rgb[:, i]) for i in range(3)])


def _board(settings: Settings, rng: np.random.Generator) -> tuple[BoardSpec, str, float]:
    paper = str(rng.choice(settings.papers))
    squares = settings.squares[int(rng.integers(len(settings.squares)))]
    board = default_board(paper, squares)
    scale = 1.0
    if rng.random() < settings.own_square_share:
        # Printed with "fit to page" or on another printer: the user measured the square.
        scale = float(rng.uniform(0.9, 0.97))
        board = board.model_copy(
            update={
                "square_mm": round(board.square_mm * scale, 2),
                "marker_mm": round((board.marker_mm or 0) * scale, 2),
            }
        )
    return board, paper, scale


def _lights(settings: Settings, rng: np.random.Generator, centre: np.ndarray) -> tuple[Light, ...]:
    out = []
    for _ in range(int(rng.integers(settings.lights[0], settings.lights[1] + 1))):
        k = rng.uniform(2800, 6500)
        power = rng.uniform(0.5, 1.5)
        w, h = rng.uniform(150, 1200), rng.uniform(150, 1200)
        xy = centre[:2] + rng.uniform(-1500, 1500, 2)
        z = -rng.uniform(1000, 2500)
        # Radiance so the irradiance at the table is of one order whatever the panel's size.
        area = w * h / 1e6
        rgb = _v3(np.array(_kelvin_rgb(k)) * power * 3.0 / area * (abs(z) / 1500) ** 2)
        out.append(Light("area", _v3([xy[0], xy[1], z]), (float(w), float(h)), rgb))
    if rng.random() < settings.window_share:
        ang = rng.uniform(0, 2 * np.pi)
        dist = rng.uniform(1500, 3000)
        c = centre + np.array([np.cos(ang) * dist, np.sin(ang) * dist, -rng.uniform(600, 1200)])
        facing = centre - c
        facing[2] = 0
        facing /= np.linalg.norm(facing)
        power = rng.uniform(0.8, 3.0)
        rgb = _v3(np.array(_kelvin_rgb(rng.uniform(5500, 8000))) * power)
        size = (float(rng.uniform(800, 1800)), float(rng.uniform(900, 1500)))
        out.append(Light("window", _v3(c), size, rgb, _v3(facing)))
    amb = rng.uniform(0.03, 0.25)
    out.append(
        Light(
            "ambient",
            (0.0, 0.0, 0.0),
            (0.0, 0.0),
            _v3(np.array(_kelvin_rgb(rng.uniform(4000, 7000))) * amb),
        )
    )
    return tuple(out)


def _clutter(
    settings: Settings,
    rng: np.random.Generator,
    sheet: tuple[float, float, float, float],
    table: tuple[float, float, float, float],
) -> tuple[Clutter, ...]:
    out = []
    x0, y0, x1, y1 = sheet
    for _ in range(int(rng.integers(settings.clutter[0], settings.clutter[1] + 1))):
        kind = str(rng.choice(["box", "mug", "ball", "cable", "ruler"]))
        for _try in range(20):
            ang = rng.uniform(0, 2 * np.pi)
            r = rng.uniform(60, 350)
            # Beside the sheet: from its edge outwards.
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            ex = (x1 - x0) / 2 * abs(np.cos(ang)) + (y1 - y0) / 2 * abs(np.sin(ang))
            x, y = cx + (ex + r) * np.cos(ang), cy + (ex + r) * np.sin(ang)
            if table[0] + 50 < x < table[2] - 50 and table[1] + 50 < y < table[3] - 50:
                break
        rgb = _v3(rng.uniform(0.03, 0.8, 3))
        if kind == "box":
            size = (rng.uniform(40, 200), rng.uniform(40, 200), rng.uniform(20, 200))
        elif kind == "mug":
            size = (rng.uniform(35, 50), 0.0, rng.uniform(70, 120))
        elif kind == "ball":
            size = (rng.uniform(15, 60), 0.0, 0.0)
        elif kind == "ruler":
            size = (rng.uniform(200, 400), rng.uniform(25, 35), rng.uniform(1, 3))
        else:
            size = (rng.uniform(2.5, 5), 0.0, 0.0)
        path: tuple[tuple[float, float], ...] = ()
        if kind == "cable":
            pts = [np.array([x, y])]
            heading = rng.uniform(0, 2 * np.pi)
            for _s in range(int(rng.integers(8, 20))):
                heading += rng.normal(0, 0.35)
                pts.append(pts[-1] + 40 * np.array([np.cos(heading), np.sin(heading)]))
            # Beside the sheet, not over it: the cable ends where it would reach the sheet.
            inside = [x0 - 20 < p[0] < x1 + 20 and y0 - 20 < p[1] < y1 + 20 for p in pts]
            pts = pts[: inside.index(True)] if True in inside else pts
            path = tuple((float(p[0]), float(p[1])) for p in pts)
        out.append(
            Clutter(
                kind,
                float(x),
                float(y),
                _v3(size),
                float(rng.uniform(0, 360)),
                rgb,
                bool(rng.random() < 0.25),
                path,
            )
        )
    if rng.random() < settings.hand_shadow_share:
        out.append(
            Clutter(
                "hand",
                float(rng.uniform(x0, x1)),
                float(rng.uniform(y0, y1)),
                (90.0, 190.0, 30.0),
                float(rng.uniform(0, 360)),
                (0.6, 0.45, 0.4),
            )
        )
    return tuple(out)


def _exposure(settings: Settings, rng: np.random.Generator) -> Exposure:
    return Exposure(
        bias_ev=float(rng.uniform(-0.4, 0.3)),
        white_balance_error=_v3(np.exp(rng.normal(0, 0.04, 3))),
        jpeg_quality=int(rng.integers(settings.jpeg_quality[0], settings.jpeg_quality[1] + 1)),
        full_well=float(rng.uniform(*settings.noise_electrons)),
    )


def _part(
    settings: Settings,
    rng: np.random.Generator,
    seed: int,
    sheet: tuple[float, float, float, float],
    size_mm: tuple[float, float],
    over_edge: bool,
) -> Part:
    material = str(rng.choice(PART_MATERIALS, p=np.array(settings.materials) / sum(settings.materials)))
    longest = _log_uniform(rng, *size_mm)
    other = longest * rng.uniform(0.3, 1.0)
    height = _log_uniform(rng, max(size_mm[0], 0.25 * longest), min(size_mm[1], 1.5 * longest))
    x0, y0, x1, y1 = sheet
    if over_edge:
        # At or over the sheet's edge: the footprint's centre within a part's size of the edge.
        side = int(rng.integers(4))
        t = rng.uniform(0.2, 0.8)
        edge = [
            (x0 + t * (x1 - x0), y0),
            (x1, y0 + t * (y1 - y0)),
            (x0 + t * (x1 - x0), y1),
            (x0, y0 + t * (y1 - y0)),
        ][side]
        inward = [(0, 1), (-1, 0), (0, -1), (1, 0)][side]
        d = rng.uniform(-0.3, 0.5) * other
        x, y = edge[0] + inward[0] * d, edge[1] + inward[1] * d
    else:
        m = min(0.5 * other, 0.3 * (x1 - x0), 0.3 * (y1 - y0))
        x, y = rng.uniform(x0 + m, x1 - m), rng.uniform(y0 + m, y1 - m)
    radius = min(float(rng.uniform(*settings.radius_mm)), 0.2 * min(other, height))
    return Part(
        longest, other, height, float(x), float(y), float(rng.uniform(0, 180)), radius, material, seed
    )


def _base(settings: Settings, rng: np.random.Generator, seed: int, camera: LensCamera) -> Scene:
    board, paper, _scale = _board(settings, rng)
    pw, ph = PAPER_MM[paper][1], PAPER_MM[paper][0]  # landscape
    bw, bh = board.size_mm
    off = ((pw - bw) / 2, min(12.0, ph - bh - 1))
    sheet_origin = (-off[0], -off[1])
    sheet = (sheet_origin[0], sheet_origin[1], sheet_origin[0] + pw, sheet_origin[1] + ph)
    tw, td = rng.uniform(900, 1800), rng.uniform(700, 1000)
    # The sheet somewhere on the table, sometimes near its edge (the edge and the floor in view).
    tx0 = sheet[0] - rng.uniform(30, tw - pw - 30)
    ty0 = sheet[1] - rng.uniform(30, td - ph - 30)
    table_ext = (float(tx0), float(ty0), float(tx0 + tw), float(ty0 + td))
    table = str(rng.choice(TABLES, p=np.array(settings.tables) / sum(settings.tables)))
    centre = np.array([bw / 2, bh / 2, 0.0])
    return Scene(
        settings=settings,
        seed=seed,
        board=board,
        paper=paper,
        paper_mm=(pw, ph),
        sheet_origin_mm=sheet_origin,
        page_board_offset_mm=off,
        ink=float(rng.uniform(0.02, 0.06)),
        paper_white=float(rng.uniform(0.72, 0.88)),
        table=table,
        table_seed=int(rng.integers(1 << 30)),
        table_extent_mm=table_ext,
        lights=_lights(settings, rng, centre),
        clutter=_clutter(settings, rng, sheet, table_ext),
        camera=camera,
        part=None,
        exposure=_exposure(settings, rng),
    )


def _camera(
    rng: np.random.Generator,
    size: tuple[int, int],
    target: np.ndarray,
    distance: float,
    elevation: float,
    f_px: float,
    k1: float,
    roll: float,
) -> LensCamera:
    az = rng.uniform(0, 2 * np.pi)
    e = np.radians(elevation)
    centre = target + distance * np.array([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az), -np.sin(e)])
    R, t = look_at(centre, target, roll)
    w, h = size
    K = np.array(
        [
            [f_px, 0, (w - 1) / 2 + rng.uniform(-12, 12)],
            [0, f_px, (h - 1) / 2 + rng.uniform(-12, 12)],
            [0, 0, 1],
        ]
    )
    dist = np.array([k1, rng.uniform(-0.02, 0.05) if k1 < 0 else 0.0, 0, 0, 0])
    return LensCamera(K, dist, R, t, size)


def _sees(camera: LensCamera, X: np.ndarray, margin: float) -> bool:
    cam = (camera.R @ X.T).T + camera.t
    if (cam[:, 2] <= 10).any():
        return False
    p = camera.project(X)
    w, h = camera.size
    return bool(((p >= margin) & (p <= np.array([w - 1 - margin, h - 1 - margin]))).all())


def station_scenes(seed: int, n_parts: int, settings: Settings) -> tuple[Scene, list[Scene]]:
    """One station: its plate (the empty support, as calibrated) and `n_parts` photos of parts
    of random size, material and place, each with its own exposure, white balance and noise.
    The camera, the table, the lights and the clutter stay."""
    rng = np.random.default_rng([seed, 40_1])
    base = _base(settings, rng, seed, _UNSET)
    bw, bh = base.board.size_mm
    sheet = (
        base.sheet_origin_mm[0],
        base.sheet_origin_mm[1],
        base.sheet_origin_mm[0] + base.paper_mm[0],
        base.sheet_origin_mm[1] + base.paper_mm[1],
    )
    d = rng.uniform(*settings.station_distance_mm) * max(bw, 250) / 300
    f = rng.uniform(0.55, 0.8) * settings.image_size[0] * d / base.paper_mm[0]
    target = np.array([bw / 2 + rng.uniform(-20, 20), bh / 2 + rng.uniform(-20, 20), 0.0])
    camera = _camera(
        rng,
        settings.image_size,
        target,
        d,
        rng.uniform(*settings.station_elevation_deg),
        f,
        rng.uniform(*settings.k1),
        0.0,
    )
    plate = replace(base, camera=camera)
    photos = []
    for i in range(n_parts):
        prng = np.random.default_rng([seed, i, 40_2])
        for _try in range(60):
            part = _part(
                settings,
                prng,
                seed * 1000 + i,
                sheet,
                settings.part_mm,
                bool(prng.random() < settings.over_edge_share),
            )
            if _sees(camera, part.corners(), 40) and part.dimensions["width"] < 0.9 * d:
                break
        photos.append(plate.with_part(part, prng))
    return plate, photos


def handheld_scene(seed: int, settings: Settings) -> Scene:
    """A photo taken by hand of a part on the printed board: close, tilted, rolled; the part may be
    tall enough to leave the board in the view, and may stand at or over the board's edge."""
    rng = np.random.default_rng([seed, 40_3])
    base = _base(settings, rng, seed, _UNSET)
    bw, bh = base.board.size_mm
    (
        base.sheet_origin_mm[0],
        base.sheet_origin_mm[1],
        base.sheet_origin_mm[0] + base.paper_mm[0],
        base.sheet_origin_mm[1] + base.paper_mm[1],
    )
    board_rect = np.array([[0, 0, 0], [bw, 0, 0], [bw, bh, 0], [0, bh, 0]], float)
    for _try in range(200):
        part = _part(
            settings,
            rng,
            seed,
            (0.0, 0.0, bw, bh),
            settings.hand_part_mm,
            bool(rng.random() < settings.over_edge_share),
        )
        w = settings.image_size[0]
        hfov = np.radians(rng.uniform(55, 72))
        f = w / 2 / np.tan(hfov / 2)
        d = rng.uniform(*settings.hand_distance_mm) * max(1.0, part.dimensions["width"] / 120)
        target = np.array([part.x_mm, part.y_mm, -part.height_mm / 3]) + np.r_[rng.uniform(-40, 40, 2), 0]
        camera = _camera(
            rng,
            settings.image_size,
            target,
            d,
            rng.uniform(*settings.hand_elevation_deg),
            f,
            rng.uniform(*settings.k1) * 0.5,
            rng.uniform(-12, 12),
        )
        # The part whole in view, and enough of the board to find it.
        corners_seen = _sees(camera, part.corners(), 25)
        board_pts = board_rect + (board_rect.mean(0) - board_rect) * 0.3
        if corners_seen and sum(_sees(camera, p[None], 5) for p in board_pts) >= 3:
            return replace(base, camera=camera, part=part)
    raise RuntimeError(f"seed {seed}: no hand-held view found")

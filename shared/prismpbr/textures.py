"""Texture images for the tables, the printed page and the parts, made from noise and drawing.

All return linear reflectance in [0, 1], float32 (H, W, 3): Mitsuba reads them raw. Colours are
chosen in sRGB (how people name them) and linearised here.
"""

from __future__ import annotations

import cv2
import numpy as np

from prismcore.station.board import BoardSpec, board_image

__all__ = [
    "fabric",
    "glossy_print",
    "kraft",
    "laminate",
    "linear",
    "printed_page",
    "printed_table",
    "wood",
]


def linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] -> linear reflectance."""
    c = np.clip(np.asarray(srgb, np.float32), 0, 1)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _noise(rng: np.random.Generator, shape: tuple[int, int], cells: tuple[int, int]) -> np.ndarray:
    low = rng.normal(0, 1, (max(cells[0], 2), max(cells[1], 2))).astype(np.float32)
    return cv2.resize(low, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)


def wood(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """Oak, walnut or pine: rings drawn as bands of a warped coordinate, pores as fine streaks."""
    h, w = size
    base = np.array(
        rng.choice([[0.62, 0.45, 0.28], [0.40, 0.27, 0.17], [0.78, 0.62, 0.42], [0.55, 0.40, 0.30]]),
        np.float32,
    ) * rng.uniform(0.85, 1.1)
    y = np.arange(h, dtype=np.float32)[:, None] * np.ones((1, w), np.float32)
    warp = 25 * _noise(rng, size, (6, 3)) + 6 * _noise(rng, size, (30, 8))
    rings = 0.5 + 0.5 * np.sin((y + warp) / rng.uniform(6, 14) * 2 * np.pi)
    streak = cv2.resize(rng.normal(0, 1, (h, max(w // 40, 2))).astype(np.float32), (w, h))
    shade = 1 + rng.uniform(0.08, 0.2) * (rings - 0.5) + 0.05 * streak
    # Planks: a dark seam every 120-200 px along the grain.
    seam = np.ones(h, np.float32)
    step = int(rng.uniform(120, 200))
    seam[::step] = 0.55
    seam = np.asarray(cv2.GaussianBlur(seam[:, None], (1, 5), 0), np.float32)[:, 0]
    img = base[None, None, :] * (shade * seam[:, None])[..., None]
    return linear(img)


def laminate(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A plain laminate: one colour with faint mottling."""
    base = np.array(
        rng.choice(
            [
                [0.85, 0.85, 0.82],
                [0.55, 0.56, 0.58],
                [0.30, 0.30, 0.32],
                [0.75, 0.70, 0.60],
                [0.35, 0.45, 0.55],
            ]
        ),
        np.float32,
    )
    img = base[None, None, :] * (1 + 0.03 * _noise(rng, size, (20, 20)))[..., None]
    return linear(img)


def fabric(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """Woven cloth: a colour, a fine weave and folds' shading."""
    h, w = size
    base = linear(rng.uniform(0.15, 0.75, 3).astype(np.float32))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    weave = 0.5 + 0.25 * (np.sin(xx * 1.7) + np.sin(yy * 1.7))
    folds = 1 + 0.12 * _noise(rng, size, (4, 4))
    return np.asarray(np.clip(base[None, None, :] * (0.8 + 0.3 * weave * folds)[..., None], 0, 1), np.float32)


def _shapes(rng: np.random.Generator, img: np.ndarray, n: int, palette: np.ndarray) -> None:
    h, w = img.shape[:2]
    for _ in range(n):
        c = tuple(float(v) for v in palette[rng.integers(len(palette))])
        kind = rng.integers(4)
        x, y = int(rng.uniform(0, w)), int(rng.uniform(0, h))
        s = int(rng.uniform(0.03, 0.3) * min(h, w))
        if kind == 0:
            cv2.rectangle(img, (x, y), (x + s, y + int(s * rng.uniform(0.2, 1.5))), c, -1)
        elif kind == 1:
            cv2.circle(img, (x, y), s // 2, c, -1, cv2.LINE_AA)
        elif kind == 2:
            cv2.line(
                img, (x, y), (int(rng.uniform(0, w)), int(rng.uniform(0, h))), c, max(1, s // 12), cv2.LINE_AA
            )
        else:
            _text(rng, img, (x, y), c, s / 60)


def _text(
    rng: np.random.Generator, img: np.ndarray, at: tuple[int, int], colour: tuple[float, ...], scale: float
) -> None:
    words = [
        "FRAGILE",
        "PART 4471-B",
        "MADE IN EU",
        "LOT 2209",
        "THIS SIDE UP",
        "Qty 12",
        "ACME",
        "12 x 250 ml",
        "REF 88-301",
        "KEEP DRY",
        "CE",
        "Nr. 00417",
    ]
    # OpenCV draws text on 8-bit images only: drawn as a coverage mask, then blended.
    mask = np.zeros(img.shape[:2], np.uint8)
    cv2.putText(
        mask,
        str(rng.choice(words)),
        at,
        cv2.FONT_HERSHEY_SIMPLEX,
        max(scale, 0.3),
        255,
        max(1, int(scale * 2)),
        cv2.LINE_AA,
    )
    a = (mask.astype(np.float32) / 255)[..., None]
    img[:] = img * (1 - a) + np.array(colour, np.float32) * a


def printed_table(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A printed pattern (an oilcloth, a cutting mat, newspaper): shapes and text in a palette."""
    palette = rng.uniform(0.05, 0.95, (5, 3)).astype(np.float32)
    img = np.empty((*size, 3), np.float32)
    img[:] = palette[0]
    _shapes(rng, img, int(rng.uniform(40, 120)), palette)
    return linear(img)


def printed_page(
    board: BoardSpec,
    paper_mm: tuple[float, float],
    px_per_mm: float,
    board_offset_mm: tuple[float, float],
    ink: float,
    paper: float,
) -> np.ndarray:
    """The sheet as `prism board` prints it: the board at 1:1, a 100 mm ruler and a text line
    under it, a white margin round them. `paper_mm` is the sheet's (width, height) as laid,
    `board_offset_mm` where the board's top-left corner lies on it. Grey levels: `ink`, `paper`
    (linear reflectance)."""
    W, H = round(paper_mm[0] * px_per_mm), round(paper_mm[1] * px_per_mm)
    page = np.full((H, W), 255, np.uint8)
    art = board_image(board, px_per_mm)
    x0, y0 = round(board_offset_mm[0] * px_per_mm), round(board_offset_mm[1] * px_per_mm)
    page[y0 : y0 + art.shape[0], x0 : x0 + art.shape[1]] = art[: H - y0, : W - x0]
    ry = y0 + art.shape[0] + round(8 * px_per_mm)
    if ry + round(8 * px_per_mm) < H:
        cv2.line(page, (x0, ry), (x0 + round(100 * px_per_mm), ry), 0, max(1, round(0.4 * px_per_mm)))
        for mm in range(0, 101, 10):
            tick = round((4 if mm % 50 else 7) * px_per_mm)
            x = x0 + round(mm * px_per_mm)
            cv2.line(page, (x, ry), (x, ry - tick), 0, max(1, round(0.4 * px_per_mm)))
        text = (
            f"100 mm check ruler: measure it after printing. ChArUco {board.squares_x}x{board.squares_y} "
            f"squares of {board.square_mm:g} mm, {board.dictionary}"
        )
        cv2.putText(
            page,
            text,
            (x0, ry + round(5 * px_per_mm)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.09 * px_per_mm,
            0,
            max(1, round(0.3 * px_per_mm)),
            cv2.LINE_AA,
        )
    grey = ink + (paper - ink) * page.astype(np.float32) / 255
    return np.repeat(grey[..., None], 3, axis=2)


def kraft(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """Kraft cardboard: brown with fibres, a printed label (text, a barcode) on some faces."""
    h, w = size
    base = np.array([0.66, 0.50, 0.33], np.float32) * rng.uniform(0.8, 1.15)
    fib = 1 + 0.06 * _noise(rng, size, (h // 3, w // 3)) + 0.04 * _noise(rng, size, (12, 12))
    img = np.clip(base[None, None, :] * fib[..., None], 0, 1)
    for cell in rng.choice(6, size=int(rng.integers(1, 4)), replace=False):
        cx, cy = (cell % 3) * w // 3, (cell // 3) * h // 2
        lw, lh = int(w / 3 * rng.uniform(0.3, 0.6)), int(h / 2 * rng.uniform(0.2, 0.5))
        lx, ly = (
            cx + int(rng.uniform(0.1, 0.9) * (w / 3 - lw)),
            cy + int(rng.uniform(0.1, 0.9) * (h / 2 - lh)),
        )
        img[ly : ly + lh, lx : lx + lw] = 0.92
        for i in range(int(lw / 5)):
            if rng.random() < 0.5:
                img[ly + lh // 2 : ly + lh - 3, lx + 3 + 2 * i : lx + 4 + 2 * i] = 0.05
        _text(rng, img, (lx + 3, ly + lh // 3), (0.05, 0.05, 0.05), lh / 90)
    # Print marks straight on the cardboard.
    _shapes(rng, img, int(rng.integers(0, 6)), np.array([[0.1, 0.1, 0.1], [0.45, 0.12, 0.1]], np.float32))
    return linear(img)


def glossy_print(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """Printed packaging: a saturated ground, shapes, text and a coloured border near the edges."""
    h, w = size
    palette = np.vstack([rng.uniform(0, 1, (4, 3)), [[0.95, 0.95, 0.95], [0.05, 0.05, 0.05]]]).astype(
        np.float32
    )
    img = np.empty((h, w, 3), np.float32)
    img[:] = palette[rng.integers(4)]
    _shapes(rng, img, int(rng.uniform(15, 50)), palette)
    if rng.random() < 0.6:  # a printed border just inside each face's edge (a box's design)
        c = tuple(float(v) for v in palette[rng.integers(len(palette))])
        t = max(2, int(rng.uniform(0.01, 0.04) * min(h, w)))
        for col in range(3):
            for row in range(2):
                x0, y0 = col * w // 3 + int(0.02 * w / 3) + t, row * h // 2 + int(0.02 * h / 2) + t
                x1, y1 = (
                    (col + 1) * w // 3 - int(0.02 * w / 3) - t,
                    (row + 1) * h // 2 - int(0.02 * h / 2) - t,
                )
                cv2.rectangle(img, (x0, y0), (x1, y1), c, t)
    return linear(img)

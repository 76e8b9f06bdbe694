"""What a scene looks like: the box's colour and the light, a cluttered background, and each face's
texture (grain, lighting gradient, a printed label).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .box_geometry import _lambert
from .models import Style

__all__: list[str] = []


_BOX_PALETTE = [
    (182, 140, 96), (196, 160, 112), (165, 120, 80),  # kraft cardboard
    (228, 226, 218), (210, 212, 214), (150, 152, 156), (88, 90, 96),  # white, greys
    (60, 95, 160), (170, 45, 45), (55, 130, 80), (215, 180, 60), (225, 120, 40),  # plastics
    (120, 80, 140), (70, 150, 160),
]


def _box_color(rng: np.random.Generator, style: Style) -> np.ndarray:
    if style.box_color is not None:
        return np.asarray(style.box_color, dtype=np.float64)
    base = np.asarray(_BOX_PALETTE[rng.integers(len(_BOX_PALETTE))], dtype=np.float64)
    return np.clip(base + rng.uniform(-15, 15, 3), 20, 240)


def _light(rng: np.random.Generator) -> np.ndarray:
    """Unit direction toward the light (world), from above and in front, chosen so that
    adjacent faces get clearly different Lambertian shades."""
    for _ in range(200):
        lx, ly, lz = rng.uniform(-0.9, 0.9), -rng.uniform(0.25, 1.0), -rng.uniform(0.45, 1.0)
        light = np.array([lx, ly, lz]) / math.sqrt(lx * lx + ly * ly + lz * lz)
        front, right, top = (_lambert(n, light) for n in ([0, 0, -1], [1, 0, 0], [0, -1, 0]))
        if abs(front - right) >= 0.12 and abs(front - top) >= 0.08 and abs(right - top) >= 0.08:
            return light
    return np.array([0.45, -0.45, -0.77])


def _random_color(rng: np.random.Generator) -> np.ndarray:
    c = rng.uniform(20, 235, 3)
    grey = c.mean()
    muted: np.ndarray = grey + (c - grey) * rng.uniform(0.15, 0.85)  # mostly muted, like real rooms
    return muted


def _contrasting(rng: np.random.Generator, face: np.ndarray, min_dist: float = 70.0) -> np.ndarray:
    for _ in range(200):
        c = _random_color(rng)
        if np.linalg.norm(c - face) >= min_dist:
            return c
    return np.where(face > 127, 40.0, 215.0)


def _near(rng: np.random.Generator, color: np.ndarray, spread: float) -> np.ndarray:
    return np.clip(color + rng.uniform(-spread, spread, 3), 0, 255)


def _low_freq(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    """Smooth random field (h, w) float32, zero mean, unit std."""
    gh, gw = max(2, round(cells * h / max(h, w))), max(2, round(cells * w / max(h, w)))
    small = rng.standard_normal((gh, gw)).astype(np.float32)
    field = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    normalised: np.ndarray = (field - field.mean()) / (field.std() + 1e-6)
    return normalised


def _background(rng: np.random.Generator, size: tuple[int, int], style: Style,
                face: np.ndarray) -> np.ndarray:
    """Background (H, W, 3) float32 RGB, 0-255. `face` is the photographed face's colour."""
    w, h = size
    if style.background_close:
        base = face + rng.uniform(-1, 1, 3) * rng.uniform(6, 11)  # ~10-19 RGB away
        family = 25.0  # shapes; the surfaces stay within about 20
    else:
        base = _contrasting(rng, face)
        family = None
    img: np.ndarray = np.empty((h, w, 3), np.float32)  # float32, uint8 to draw on, float32
    img[:] = base
    if not style.clutter:
        return img

    def color(strong: bool = False) -> tuple[float, ...]:
        if family is not None:
            c = _near(rng, base, family)
        elif strong or rng.random() < 0.6:
            c = _random_color(rng)
        else:
            c = _near(rng, base, 45.0)
        return tuple(float(v) for v in c)

    # Smooth gradient and blotches (uneven light on a wall or a table).
    ang = rng.uniform(0, 2 * math.pi)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    ramp = ((xx - w / 2) * math.cos(ang) + (yy - h / 2) * math.sin(ang)) / max(w, h)
    amp = 8.0 if family is not None else 30.0
    img += (ramp * amp * 2)[..., None]
    img += (_low_freq(rng, h, w, 6) * amp * 0.4)[..., None]
    # A table edge: a straight line across the picture with another surface beyond it.
    if rng.random() < 0.7:
        y_left, y_right = rng.uniform(0.05, 0.95, 2) * h
        beyond = np.asarray(color() if family is None else _near(rng, base, 14.0), np.float32)
        mask = np.zeros((h, w), np.uint8)
        upper = rng.random() < 0.5
        pts = [(0, y_left), (w - 1, y_right), (w - 1, 0 if upper else h - 1), (0, 0 if upper else h - 1)]
        cv2.fillPoly(mask, [np.round(np.array(pts) * 16).astype(np.int32)], 255, cv2.LINE_AA, shift=4)
        m = (mask.astype(np.float32) / 255)[..., None]
        img = img * (1 - m) + (beyond + (_low_freq(rng, h, w, 4) * amp * 0.3)[..., None]) * m
    # OpenCV draws text (and anti-aliased shapes) on 8-bit images only.
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    # Shapes: boxes, discs, triangles, some outlined, some translucent.
    scale = max(w, h)
    for _ in range(int(rng.integers(12, 26))):
        layer = img.copy()
        c = color()
        kind = rng.integers(4)
        cx, cy = rng.uniform(-0.05, 1.05) * w, rng.uniform(-0.05, 1.05) * h
        r = rng.uniform(0.02, 0.15) * scale
        thick = -1 if rng.random() < 0.7 else int(rng.integers(2, 6))
        if kind == 0 or kind == 1:
            ang = rng.uniform(0, 180) if kind == 1 else rng.choice([0.0, 90.0]) + rng.normal(0, 3)
            rect = ((cx, cy), (r * rng.uniform(0.6, 2.0), r * rng.uniform(0.3, 1.5)), ang)
            poly = cv2.boxPoints(rect)
            _poly(layer, poly, c, thick)
        elif kind == 2:
            axes = (round(r * 16), round(r * rng.uniform(0.4, 1.0) * 16))
            cv2.ellipse(layer, (round(cx * 16), round(cy * 16)), axes, rng.uniform(0, 180), 0, 360, c,
                        thick, cv2.LINE_AA, 4)
        else:
            poly = np.array([cx, cy]) + rng.uniform(-r, r, (3, 2))
            _poly(layer, poly, c, thick)
        alpha = 1.0 if rng.random() < 0.75 else rng.uniform(0.3, 0.7)
        img = layer if alpha == 1.0 else cv2.addWeighted(layer, alpha, img, 1 - alpha, 0)
    # Straight lines: cables, shelf and tile edges, pencils.
    for _ in range(int(rng.integers(6, 16))):
        p = rng.uniform(-0.1, 1.1, 2) * (w, h)
        ang = rng.uniform(0, math.pi)
        length = rng.uniform(0.1, 1.2) * scale
        q = p + length * np.array([math.cos(ang), math.sin(ang)])
        cv2.line(img, _fix(p), _fix(q), color(strong=True), int(rng.integers(1, 5)), cv2.LINE_AA, 4)
    # Text-like marks (a newspaper, a printed sheet).
    for _ in range(int(rng.integers(1, 4))):
        x, y = rng.uniform(0, 0.9) * w, rng.uniform(0.05, 0.95) * h
        c = color(strong=True)
        font_scale = rng.uniform(0.4, 1.0)
        for line in range(int(rng.integers(2, 6))):
            cv2.putText(img, _words(rng, 14), (round(x), round(y + line * 30 * font_scale)),
                        cv2.FONT_HERSHEY_SIMPLEX, font_scale, c, 1, cv2.LINE_AA)
    # Fine grain of the surfaces.
    img = img.astype(np.float32)
    grain = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 0.8)
    img += (grain * (1.5 + 0.5 * style.texture))[..., None]
    return img


def _fix(p: np.ndarray) -> tuple[int, int]:
    """A point in OpenCV's 4-bit fixed point (shift=4)."""
    return round(float(p[0]) * 16), round(float(p[1]) * 16)


def _poly(img: np.ndarray, poly: np.ndarray, color: tuple[float, ...], thick: int) -> None:
    pts = [np.round(np.asarray(poly) * 16).astype(np.int32)]
    if thick < 0:
        cv2.fillPoly(img, pts, color, cv2.LINE_AA, shift=4)
    else:
        cv2.polylines(img, pts, True, color, thick, cv2.LINE_AA, shift=4)


def _fit_text(rng: np.random.Generator, room: int, scale: float, thick: int) -> str:
    """Random words that fit in `room` px, stopping at a random fill of the line."""
    goal = room * rng.uniform(0.4, 1.0)
    text = ""
    for _ in range(20):
        longer = (text + " " if text else "") + _words(rng, 1)
        width = cv2.getTextSize(longer, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0]
        if width > goal:
            break
        text = longer
    return text


def _words(rng: np.random.Generator, n: int) -> str:
    letters = "ABCDEFGHIJKLMNOPRSTUVWXYZ0123456789"
    out: list[str] = []
    while sum(len(x) + 1 for x in out) < n:
        out.append("".join(letters[i] for i in rng.integers(len(letters), size=int(rng.integers(2, 8)))))
    return " ".join(out)


def _grain(rng: np.random.Generator, nv: int, nu: int, amplitude: float) -> np.ndarray:
    """Grain + fibres + mottling (nv, nu) float32 with std about `amplitude`."""
    if amplitude <= 0:
        return np.zeros((nv, nu), np.float32)
    fine = cv2.GaussianBlur(rng.standard_normal((nv, nu)).astype(np.float32), (0, 0), 0.7)
    fibres: np.ndarray = rng.standard_normal((nv, nu)).astype(np.float32)
    horizontal = rng.random() < 0.5
    fibres = cv2.GaussianBlur(fibres, (0, 0), sigmaX=6.0 if horizontal else 0.6,
                              sigmaY=0.6 if horizontal else 6.0)
    mottle = _low_freq(rng, nv, nu, 8)
    out = (0.75 * fine / (fine.std() + 1e-6) + 0.45 * fibres / (fibres.std() + 1e-6)
           + 0.45 * mottle)
    grain: np.ndarray = out * amplitude
    return grain


def _lighting_field(rng: np.random.Generator, nv: int, nu: int, strength: float) -> np.ndarray:
    """Multiplicative lighting (nv, nu) float32: 1 +- strength/2, smooth."""
    if strength <= 0:
        return np.ones((nv, nu), np.float32)
    v, u = np.mgrid[0:nv, 0:nu].astype(np.float32)
    u, v = u / max(nu - 1, 1) - 0.5, v / max(nv - 1, 1) - 0.5
    ang = rng.uniform(0, 2 * math.pi)
    ramp = u * math.cos(ang) + v * math.sin(ang)
    hx, hy = rng.uniform(-0.5, 0.5, 2)
    spot = np.exp(-((u - hx) ** 2 + (v - hy) ** 2) / (2 * rng.uniform(0.2, 0.5) ** 2))
    g = 0.7 * ramp + 0.5 * spot
    g = (g - g.min()) / (np.ptp(g) + 1e-6) - 0.5  # exactly spans [-0.5, 0.5]
    field: np.ndarray = 1.0 + strength * g
    return field


def _draw_label(rng: np.random.Generator, albedo: np.ndarray, texture: float) -> None:
    """Paint a printed label (paper, barcode, text, logo) on (nv, nu, 3) albedo, in place,
    inset at least 12% of the face's size from its edges."""
    nv, nu = albedo.shape[:2]
    lw = int(nu * rng.uniform(0.35, 0.7))
    lh = int(nv * rng.uniform(0.3, 0.6))
    lw, lh = min(lw, int(0.74 * nu)), min(lh, int(0.74 * nv))
    if lw < 12 or lh < 8:
        return
    x0 = int(rng.uniform(0.13 * nu, 0.87 * nu - lw))
    y0 = int(rng.uniform(0.13 * nv, 0.87 * nv - lh))
    paper = np.clip(rng.choice([245.0, 238.0, 230.0]) + rng.uniform(-8, 8, 3), 200, 252)
    if rng.random() < 0.25:  # a coloured label
        paper = np.clip(_random_color(rng) * 0.4 + 150, 0, 250)
    ink = np.clip(rng.uniform(10, 50, 3), 0, 255)
    lab = np.empty((lh, lw, 3), np.uint8)
    lab[:] = np.round(paper).astype(np.uint8)
    ink_t = tuple(int(c) for c in ink)
    # Border.
    if rng.random() < 0.6:
        m = max(2, lw // 40)
        cv2.rectangle(lab, (m, m), (lw - 1 - m, lh - 1 - m), ink_t, max(1, lw // 150), cv2.LINE_AA)
    # Barcode in a lower part of the label.
    bw, bh = int(lw * rng.uniform(0.35, 0.6)), int(lh * rng.uniform(0.2, 0.35))
    bx, by = int(lw * rng.uniform(0.06, 0.94) - bw * rng.uniform(0, 1)), int(lh * 0.9) - bh
    bx = min(max(bx, lw // 15), lw - bw - lw // 15)
    unit = max(1.0, bw / 95.0)
    x = float(bx)
    while x < bx + bw:
        width = unit * rng.integers(1, 4)
        if rng.random() < 0.5:
            cv2.rectangle(lab, (round(x), by), (max(round(x), round(x + width) - 1), by + bh), ink_t, -1)
        x += width
    # A logo in the upper right corner.
    r = max(3, min(lw, lh) // 10)
    logo_left = lw
    if rng.random() < 0.7:
        c = tuple(int(v) for v in np.clip(_random_color(rng) * 1.2, 0, 255))
        cx, cy = lw - lw // 12 - r, lh // 12 + r
        logo_left = cx - r
        if rng.random() < 0.5:
            cv2.circle(lab, (cx, cy), r, c, -1, cv2.LINE_AA)
        else:
            cv2.rectangle(lab, (cx - r, cy - r), (cx + r, cy + r), c, -1)
    # Lines of text above the barcode, each fitted to the room it has.
    font_h = max(6, lh // int(rng.integers(9, 15)))
    scale = font_h / 22.0
    thick = max(1, round(scale * rng.uniform(1.0, 2.0)))
    left = lw // 12
    y = lh // 12 + font_h
    while y < by - font_h // 2:
        right = logo_left - lw // 30 if y - font_h < lh // 12 + 2 * r + 4 else lw - lw // 12
        text = _fit_text(rng, right - left, scale, thick)
        if text:
            cv2.putText(lab, text, (left, y), cv2.FONT_HERSHEY_SIMPLEX, scale, ink_t, thick, cv2.LINE_AA)
        y += int(font_h * rng.uniform(1.4, 1.9))
    region = lab.astype(np.float32)
    if texture > 0:
        region += (cv2.GaussianBlur(rng.standard_normal((lh, lw)).astype(np.float32), (0, 0), 0.7)
                   * texture * 0.5)[..., None]
    albedo[y0:y0 + lh, x0:x0 + lw] = region

"""The overlay picture of a scan's fit: clicks, fitted faces and corners drawn on the photo.

:func:`draw_overlay` draws on a copy of an RGB photo, from explicit arrays:

* each click as a magenta cross with a gap at its centre (the clicked pixel stays visible) and a
  label (``P1`` ... ``P7``; clicks on the same spot share one label, ``P2/P4``);
* each fitted face quad as an anti-aliased outline, front azure and side amber, placed to
  1/16 px (OpenCV's fixed-point ``shift``), with a small circle on each fitted corner;
* for a click whose residual exceeds ``warn_px``, a red line from the click to its fitted corner
  and the residual in its label (``P3 4.2 px``);
* a legend panel (title, notes such as the dimensions with their uncertainty, alerts, and a key
  of the colours) in a corner (or the middle of a side) where it hides none of the drawing;
  shorter, or left out, when the drawing fills the photo.

Lines, markers and text scale with the image (one unit is a thousandth of its longer side), so
a 640 px frame and a 4000 px photo read alike. Every drawn stroke has a dark halo, so it stands
out on light and dark photos. Pixels away from the drawing are the input's, converted to uint8.

`prismcore.outputs.overlay_report` reads a scan's report and calls :func:`draw_overlay` for the
front or the side photo. Nothing here reads or writes files; callers encode the PNG (RGB -> BGR
at their boundary).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from prismcore.errors import InputError

__all__ = [
    "CLICK_COLOR",
    "FACE_COLORS",
    "LABEL_COLOR",
    "RESIDUAL_COLOR",
    "SECOND_FACE_CORNERS",
    "draw_overlay",
]

Color = tuple[int, int, int]
FACE_COLORS: dict[str, Color] = {"front": (0, 190, 255), "side": (255, 176, 0)}
"""Outline colour (RGB) of each face."""
CLICK_COLOR: Color = (255, 40, 200)
RESIDUAL_COLOR: Color = (255, 64, 64)
LABEL_COLOR: Color = (255, 255, 255)
"""Colour of every label's text (and of the legend's notes)."""
ALERT_COLOR: Color = (255, 205, 80)
HALO_COLOR: Color = (12, 12, 14)
PANEL_COLOR: Color = (20, 22, 28)
PANEL_ALPHA = 0.78

CORNER_OF: dict[str, tuple[str, int]] = {
    "p1": ("front", 0), "p2": ("front", 1), "p3": ("front", 2), "p6": ("front", 3),
    "p4": ("side", 0), "p5": ("side", 1), "p7": ("side", 2),
}
"""The fitted corner each click marks: (face, corner index in TL TR BR BL order)."""
SECOND_FACE_CORNERS: dict[str, dict[str, tuple[str, int]]] = {
    "right": {"p4": ("side", 0), "p5": ("side", 1), "p7": ("side", 2)},
    "left": {"p4": ("side", 1), "p5": ("side", 0), "p7": ("side", 3)},
    "top": {"p4": ("side", 3), "p5": ("side", 0), "p7": ("side", 1)},
}
"""In one photo, the side quad's corner P4, P5 and P7 mark for each second face (see
`prismcore.geometry.faces`); the side quad is as photographed."""
_SHIFT = 4  # OpenCV fixed point: coordinates in 1/16 px
_ONE = 1 << _SHIFT


@dataclass(frozen=True)
class _Sizes:
    """Stroke and text sizes in px for one image, all from its longer side."""

    line: int
    halo: int
    arm: float
    gap: float
    radius: float
    font: int

    @classmethod
    def for_shape(cls, height: int, width: int) -> _Sizes:
        u = max(height, width) / 1000.0
        line = max(2, round(2.2 * u))
        # the cross's gap is wider than the corner ring, so a click on its fitted corner reads
        # as one crosshair and a click off it shows its centre outside the ring
        radius = max(3.5, 5.0 * u)
        return cls(line=line, halo=max(1, round(1.2 * u)), arm=max(11.0, 20.0 * u),
                   gap=radius + max(1.5, 2.0 * u), radius=radius, font=max(12, round(19 * u)))


def _fx(points: np.ndarray) -> np.ndarray:
    return np.rint(np.asarray(points, dtype=np.float64) * _ONE).astype(np.int32)


def _as_rgb8(image: np.ndarray) -> np.ndarray:
    """A contiguous uint8 (H, W, 3) copy: grey (H, W) or (H, W, 1) is repeated, float is rounded."""
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise InputError(f"overlay needs an (H, W, 3) RGB or (H, W) grey image, got shape {arr.shape}")
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr).copy()
    if arr.dtype.kind not in "fiu":
        raise InputError(f"overlay needs a numeric image, got dtype {arr.dtype}")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise InputError("overlay image has NaN or infinite pixels")
    # float32 images are 0..255 units (16-bit photos divided by 257), so round, never rescale
    return np.ascontiguousarray(np.clip(np.rint(arr), 0, 255).astype(np.uint8))


def _point(name: str, value: object) -> np.ndarray:
    try:
        p = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"click {name}: {value!r} is not an (x, y) point") from None
    if p.shape != (2,) or not np.isfinite(p).all():
        raise InputError(f"click {name}: {value!r} is not a finite (x, y) point")
    return p


def _quad(name: str, value: object) -> np.ndarray:
    try:
        q = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"face {name}: {value!r} is not a (4, 2) array of corners") from None
    if q.shape != (4, 2) or not np.isfinite(q).all():
        raise InputError(f"face {name}: corners {value!r} are not a finite (4, 2) array")
    return q


@lru_cache(maxsize=16)
def _font(size: int) -> ImageFont.FreeTypeFont:
    # Pillow's bundled scalable font: the same glyphs (and the ± sign) on every host
    return ImageFont.load_default(size=size)  # type: ignore[return-value]


@dataclass
class _Text:
    x: float  # left end of the baseline
    y: float
    text: str
    color: Color


@dataclass
class _Panel:
    x0: int
    y0: int
    x1: int
    y1: int
    color: Color
    alpha: float


class _Layout:
    """What is drawn after the geometry: translucent panels, then text over them."""

    def __init__(self, sizes: _Sizes, shape: tuple[int, int]) -> None:
        self.sizes, self.height, self.width = sizes, shape[0], shape[1]
        self.font = _font(sizes.font)
        self.cap = -self.font.getbbox("H", anchor="ls")[1]  # cap height, px
        self.pad = max(3, round(0.35 * sizes.font))
        self.panels: list[_Panel] = []
        self.texts: list[_Text] = []

    def text_width(self, text: str) -> float:
        return float(self.font.getlength(text))

    def pill_size(self, text: str) -> tuple[int, int]:
        return math.ceil(self.text_width(text)) + 2 * self.pad, round(self.cap) + 2 * self.pad

    def clamp(self, x0: float, y0: float, w: int, h: int) -> tuple[int, int, int, int]:
        """The box of size (w, h) with its top-left near (x0, y0), moved inside the image."""
        x = round(min(max(float(x0), 0.0), self.width - w))
        y = round(min(max(float(y0), 0.0), self.height - h))
        return x, y, x + w, y + h

    def pill(self, text: str, x0: int, y0: int, fill: Color) -> None:
        """A label in a filled box with its top-left at (x0, y0)."""
        w, h = self.pill_size(text)
        self.panels.append(_Panel(x0, y0, x0 + w, y0 + h, fill, 0.92))
        self.texts.append(_Text(x0 + self.pad, y0 + self.pad + self.cap, text, LABEL_COLOR))


def _blend_box(canvas: np.ndarray, panel: _Panel, radius: int) -> None:
    x0, y0 = max(panel.x0, 0), max(panel.y0, 0)
    x1, y1 = min(panel.x1, canvas.shape[1]), min(panel.y1, canvas.shape[0])
    if x1 <= x0 or y1 <= y0:
        return
    h, w = panel.y1 - panel.y0, panel.x1 - panel.x0
    mask = np.zeros((h, w), np.uint8)
    r = max(0, min(radius, h // 2, w // 2))
    # a rounded rectangle: two crossing rectangles and four corner discs
    cv2.rectangle(mask, (r, 0), (w - 1 - r, h - 1), 255, -1)
    cv2.rectangle(mask, (0, r), (w - 1, h - 1 - r), 255, -1)
    for cx, cy in ((r, r), (w - 1 - r, r), (r, h - 1 - r), (w - 1 - r, h - 1 - r)):
        cv2.circle(mask, (cx, cy), r, 255, -1, cv2.LINE_AA)
    a = (mask[y0 - panel.y0:y1 - panel.y0, x0 - panel.x0:x1 - panel.x0].astype(np.float32)
         * (panel.alpha / 255.0))[:, :, None]
    region = canvas[y0:y1, x0:x1].astype(np.float32)
    color = np.asarray(panel.color, np.float32)
    canvas[y0:y1, x0:x1] = np.rint(region * (1 - a) + color * a).astype(np.uint8)


def _cross(center: np.ndarray, sizes: _Sizes) -> list[np.ndarray]:
    out = []
    for step in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        d = np.asarray(step, np.float64)
        out.append(np.stack([center + d * sizes.gap, center + d * sizes.arm]))
    return out


def _group_clicks(clicks: dict[str, np.ndarray], within: float) -> list[list[str]]:
    """Clicks closer than `within` px share one label (single-photo P2 and P4 usually do)."""
    groups: list[list[str]] = []
    for name in sorted(clicks, key=lambda n: (len(n), n)):
        for group in groups:
            if np.linalg.norm(clicks[group[0]] - clicks[name]) <= within:
                group.append(name)
                break
        else:
            groups.append([name])
    return groups


def _legend(layout: _Layout, title: str, notes: Sequence[str], alerts: Sequence[str],
            key: list[tuple[str, Color, str]], ink: np.ndarray, inside: np.ndarray,
            ) -> list[tuple[Color, np.ndarray, str]] | None:
    """Lay out the legend panel where it hides nothing of `ink` (outlines, markers, labels) and
    the least of `inside` (the faces); returns the key's swatches to draw on it, or None (and
    lays out nothing) when every place would hide some of `ink`."""
    s, pad = layout.sizes, round(0.7 * layout.sizes.font)
    row = round(1.45 * s.font)
    swatch = round(1.6 * s.font)
    lines = [(title, LABEL_COLOR)] if title else []
    lines += [(n, LABEL_COLOR) for n in notes] + [(a, ALERT_COLOR) for a in alerts]
    key_w = sum(swatch + 0.4 * s.font + layout.text_width(text) for text, _, _ in key)
    key_w += 0.9 * s.font * max(0, len(key) - 1)
    width = math.ceil(max([layout.text_width(t) for t, _ in lines] + [key_w])) + 2 * pad
    height = row * (len(lines) + (1 if key else 0)) - (row - round(layout.cap)) + 2 * pad
    if lines and key:
        height += round(0.35 * s.font)  # a little air above the key
    margin = round(0.8 * s.font)
    if width + 2 * margin > layout.width or height + 2 * margin > layout.height:
        return None  # the photo is too small for a legend that would not hide the fit
    right, bottom = layout.width - margin - width, layout.height - margin - height
    # corners first (in reading order), then the middles of the sides; min() keeps the first
    candidates = [(margin, margin), (right, margin), (margin, bottom), (right, bottom),
                  ((layout.width - width) // 2, margin), ((layout.width - width) // 2, bottom),
                  (margin, (layout.height - height) // 2), (right, (layout.height - height) // 2)]

    def hidden(c: tuple[int, int]) -> tuple[int, int]:
        box = (slice(c[1], c[1] + height), slice(c[0], c[0] + width))
        return int(ink[box].sum()), int(inside[box].sum())

    x0, y0 = min(candidates, key=hidden)
    if hidden((x0, y0))[0]:
        return None
    layout.panels.append(_Panel(x0, y0, x0 + width, y0 + height, PANEL_COLOR, PANEL_ALPHA))
    base = y0 + pad + layout.cap
    for i, (text, color) in enumerate(lines):
        layout.texts.append(_Text(x0 + pad, base + i * row, text, color))
    swatches = []
    if key:
        y = base + len(lines) * row + (round(0.35 * s.font) if lines else 0)
        x = float(x0 + pad)
        mid = y - layout.cap / 2
        for text, color, kind in key:
            swatches.append((color, np.array([[x, mid], [x + swatch, mid]]), kind))
            x += swatch + 0.4 * s.font
            layout.texts.append(_Text(x, y, text, LABEL_COLOR))
            x += layout.text_width(text) + 0.9 * s.font
    return swatches


def _dashed_sides(canvas: np.ndarray, quad: np.ndarray, sides: Sequence[int], sizes: _Sizes) -> None:
    """Dashes in the click colour along the given sides of a face (those the clicks set)."""
    dash = 4.0 * max(sizes.line, 1)
    for i in sides:
        if not 0 <= int(i) < 4:
            raise InputError(f"a face's side index must be 0-3, got {i!r}")
        a, b = quad[int(i)], quad[(int(i) + 1) % 4]
        length = float(np.linalg.norm(b - a))
        count = max(1, int(length / (2 * dash)))
        for k in range(count):
            t0, t1 = (2 * k + 0.5) / (2 * count), (2 * k + 1.5) / (2 * count)
            seg = np.stack([a + t0 * (b - a), a + t1 * (b - a)])
            cv2.polylines(canvas, [_fx(seg).reshape(-1, 1, 2)], False, CLICK_COLOR, sizes.line,
                          cv2.LINE_AA, _SHIFT)


def draw_overlay(
    image: np.ndarray,
    clicks: Mapping[str, Sequence[float] | np.ndarray],
    faces: Mapping[str, Sequence[Sequence[float]] | np.ndarray],
    *,
    residuals: Mapping[str, float] | None = None,
    notes: Sequence[str] = (),
    alerts: Sequence[str] = (),
    title: str = "",
    warn_px: float = 3.0,
    side_face: str = "right",
    points_key: str = "click",
    clicked_sides: Mapping[str, Sequence[int]] | None = None,
) -> np.ndarray:
    """Draw the clicks and the fitted faces on a copy of `image`.

    Parameters
    ----------
    image : ndarray, (H, W, 3) RGB or (H, W) grey, uint8 or float in 0..255 units
        The photo the points refer to. Float pixels are rounded and clipped to 0..255.
    clicks : mapping of name -> (x, y)
        Clicked reference points in image px ((0, 0) is the top-left pixel's centre); names
        among ``p1`` ... ``p7``, drawn as crosses labelled ``P1`` ... ``P7``.
    faces : mapping of ``"front"`` / ``"side"`` -> (4, 2) array_like of float
        Fitted face corners (x, y) px, top-left, top-right, bottom-right, bottom-left.
    residuals : mapping of name -> float px, optional
        The fit's distance from each click to the model. None: the distance from each click to
        the fitted corner it marks (``CORNER_OF``) is used. An empty mapping: no residuals shown.
    notes, alerts : sequence of str
        Legend lines, in the label colour and in amber. The legend goes where it hides no
        outline, marker or label (and as little of the faces as it can); where it would, it
        goes without its title and colour key, and where even that would, it is left out (the
        figures are in the report). No notes and no alerts: no legend.
    title : str
        First line of the legend.
    warn_px : float
        A residual above this many px gets a red line to its fitted corner and its value in
        the click's label.
    side_face : {"right", "left", "top"}
        The second face P4, P5 and P7 mark (``SECOND_FACE_CORNERS``), named so in the key.
    points_key : str
        What the key calls the crosses: "click", or "found point" for points the search found.
    clicked_sides : mapping of face name -> side indices (0 top, 1 right, 2 bottom, 3 left)
        Sides that rest on the clicks, not on an edge the photo showed: drawn dashed in the
        click colour over the face's outline (the report's ``fit.edges`` says why).

    Returns
    -------
    ndarray, (H, W, 3) uint8
        The picture, RGB.

    Raises
    ------
    InputError
        A bad image shape or dtype, an unknown click or face name, or a point or corner that is
        not finite.
    """
    canvas = _as_rgb8(image)
    H, W = canvas.shape[:2]
    pts: dict[str, np.ndarray] = {}
    for name, value in clicks.items():
        if name not in CORNER_OF:
            raise InputError(f"unknown click name {name!r} (expected one of {', '.join(CORNER_OF)})")
        pts[name] = _point(name, value)
    quads: dict[str, np.ndarray] = {}
    for name, corners in faces.items():
        if name not in FACE_COLORS:
            raise InputError(f"unknown face name {name!r} (expected front or side)")
        quads[name] = _quad(name, corners)
    if side_face not in SECOND_FACE_CORNERS:
        raise InputError(f"side_face must be right, left or top, got {side_face!r}")
    corner_of = {**CORNER_OF, **SECOND_FACE_CORNERS[side_face]}
    if not math.isfinite(warn_px) or warn_px < 0:
        raise InputError(f"warn_px must be a finite number >= 0, got {warn_px!r}")

    sizes = _Sizes.for_shape(H, W)
    fitted = {n: quads[f][i] for n, (f, i) in corner_of.items() if n in pts and f in quads}
    if residuals is None:
        shown = {n: float(np.linalg.norm(pts[n] - c)) for n, c in fitted.items()}
    else:
        shown = {n: float(v) for n, v in residuals.items() if n in pts and math.isfinite(float(v))}
    moved = {n for n, r in shown.items() if r > warn_px}

    # (polyline or ring centre, closed/ring, colour, thickness) in drawing order: faces, their
    # corner rings, clicks, residual lines; all halos go under all colours. The front face
    # goes after the side, so the edge and corner they share show the front's colour.
    marks: list[tuple[np.ndarray, str, Color, int]] = []
    for name in ("side", "front"):
        if name in quads:
            marks.append((quads[name], "closed", FACE_COLORS[name], sizes.line))
    for name in ("side", "front"):
        if name in quads:
            marks += [(c, "ring", FACE_COLORS[name], max(1, sizes.line - 1)) for c in quads[name]]
    for name in pts:
        marks += [(arm, "open", CLICK_COLOR, max(2, sizes.line - 1)) for arm in _cross(pts[name], sizes)]
    for name in sorted(moved & fitted.keys()):
        if np.linalg.norm(pts[name] - fitted[name]) > 1.0:
            marks.append((np.stack([pts[name], fitted[name]]), "open", RESIDUAL_COLOR,
                          max(2, sizes.line - 1)))
    r16 = round(sizes.radius * _ONE)
    for color_pass in (False, True):
        for geometry, kind, color, thick in marks:
            stroke = color if color_pass else HALO_COLOR
            width = thick + (0 if color_pass else 2 * sizes.halo)
            if kind == "ring":
                cv2.circle(canvas, tuple(int(v) for v in _fx(geometry)), r16, stroke, width,
                           cv2.LINE_AA, _SHIFT)
            else:
                cv2.polylines(canvas, [_fx(geometry).reshape(-1, 1, 2)], kind == "closed", stroke, width,
                              cv2.LINE_AA, _SHIFT)

    for name, sides in (clicked_sides or {}).items():
        if name in quads:
            _dashed_sides(canvas, quads[name], sides, sizes)

    layout = _Layout(sizes, (H, W))
    # ink: what a label or the legend should not cover (outlines, markers, labels placed so far)
    ink = np.zeros((H, W), np.uint8)
    for quad in quads.values():
        cv2.polylines(ink, [_fx(quad).reshape(-1, 1, 2)], True, 1, round(2 * sizes.radius),
                      cv2.LINE_8, _SHIFT)
    for p in pts.values():
        cv2.circle(ink, tuple(int(v) for v in _fx(p)), round(sizes.arm * _ONE), 1, -1, cv2.LINE_8, _SHIFT)
    drawn = list(pts.values()) + [c for q in quads.values() for c in q]
    centroid = np.mean(drawn, axis=0) if drawn else np.array([W / 2, H / 2])
    for group in _group_clicks(pts, within=sizes.arm):
        at = pts[group[0]]
        text = "/".join(n.upper() for n in group)
        worst = max((shown[n] for n in group if n in moved), default=None)
        if worst is not None:
            text += f"  {worst:.1f} px"
        away = at - centroid
        norm = float(np.linalg.norm(away))
        away = away / norm if norm > 1e-9 else np.array([-1.0, -1.0]) / math.sqrt(2)
        w, h = layout.pill_size(text)
        # outwards from the drawing, past the cross's arm; turned when that spot is taken
        best: tuple[int, tuple[int, int, int, int]] | None = None
        for turn in (0, 30, -30, 60, -60, 90, -90, 135, -135, 180):
            c, s_ = math.cos(math.radians(turn)), math.sin(math.radians(turn))
            d = np.array([c * away[0] - s_ * away[1], s_ * away[0] + c * away[1]])
            center = at + d * (sizes.arm + 0.4 * sizes.font) + d * np.array([w, h]) / 2
            box = layout.clamp(center[0] - w / 2, center[1] - h / 2, w, h)
            cost = int(ink[max(box[1], 0):box[3], max(box[0], 0):box[2]].sum())
            if best is None or cost < best[0]:
                best = (cost, box)
            if cost == 0:
                break
        assert best is not None
        x0, y0, x1, y1 = best[1]
        layout.pill(text, x0, y0, RESIDUAL_COLOR if worst is not None else CLICK_COLOR)
        ink[max(y0, 0):y1, max(x0, 0):x1] = 1

    face_names = {"front": "front", "side": {"left": "left side", "top": "top"}.get(side_face, "side")}
    key: list[tuple[str, Color, str]] = [(f"{face_names[n]} face", FACE_COLORS[n], "line")
                                         for n in FACE_COLORS if n in quads]
    if pts:
        key.append((points_key, CLICK_COLOR, "cross"))
    if moved & fitted.keys():
        key.append((f"> {warn_px:g} px from fit", RESIDUAL_COLOR, "line"))
    swatches: list[tuple[Color, np.ndarray, str]] | None = []
    if notes or alerts:
        inside = np.zeros((H, W), np.uint8)
        for quad in quads.values():  # the legend had better not hide the box either
            cv2.fillPoly(inside, [_fx(quad).reshape(-1, 1, 2)], 1, cv2.LINE_8, _SHIFT)
        # where the whole legend would hide part of the drawing, a shorter one may not
        swatches = _legend(layout, title, notes, alerts, key, ink, inside)
        if swatches is None:
            swatches = _legend(layout, "", notes, alerts, [], ink, inside)
    swatches = swatches or []

    for panel in layout.panels:
        _blend_box(canvas, panel, radius=round(0.3 * (panel.y1 - panel.y0)) if panel.alpha > 0.9
                   else round(0.5 * sizes.font))
    for color, seg, kind in swatches:
        if kind == "cross":
            mid = seg.mean(axis=0)
            half = 0.5 * (seg[1, 0] - seg[0, 0])
            arms = [np.stack([mid - d * half, mid + d * half]) for d in (np.array([1.0, 0]),
                                                                         np.array([0, 1.0]))]
        else:
            arms = [seg]
        for arm in arms:
            cv2.polylines(canvas, [_fx(arm).reshape(-1, 1, 2)], False, color, sizes.line,
                          cv2.LINE_AA, _SHIFT)
    if layout.texts:
        picture = Image.fromarray(canvas)
        pen = ImageDraw.Draw(picture)
        for t in layout.texts:
            pen.text((t.x, t.y), t.text, fill=t.color, font=layout.font, anchor="ls")
        canvas = np.asarray(picture).copy()
    return canvas

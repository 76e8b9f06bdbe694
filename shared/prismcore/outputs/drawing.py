"""The part's inspection sheet, laid out: an A4 landscape drawing of the measured box.

Pure geometry: `inspection_sheet` turns a `Part` into lines, filled polygons (arrow heads) and
texts in sheet millimetres (origin top-left, y down, as SVG and PDF place them); the writers
(`prismcore.outputs.drawing_files`) put them into SVG and PDF, and draw the DXF from the part
itself at true size.

What the sheet shows, third-angle projection: the front view (width x height) with the width
below it and the height to its left, the top view (width x depth) above it, the right side view
(depth x height) to its right with the depth below it, an isometric view; every dimension as
``value ± one sigma`` and its verdict (`part.dimension_text`); a table of the dimensions (measured,
± 1 s.d., nominal, tolerance, deviation, verdict) and the part's verdict; the title block: the
photo's name, the date, the scale's source, the drawing's scale, the frame of the solid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime

from prismcore.outputs.part import Dimension, Part, dimension_text

__all__ = ["DRAWING_SCALES", "SHEET_SIZE", "VERDICT_COLOURS", "Line", "Polygon", "Sheet", "Text",
           "drawing_scale", "inspection_sheet", "isometric", "scale_text"]

SHEET_SIZE = (297.0, 210.0)
"""A4 landscape, mm."""

DRAWING_SCALES = (10.0, 5.0, 2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001)
"""The standard drawing scales (ISO 5455) the views may be drawn at, largest first."""

THICK, THIN = 0.5, 0.25  # line widths, mm (ISO 128: visible outlines, dimension lines)
TEXT_MM = 3.0  # dimension text height
_GAP = 22.0  # between views, room for a dimension and its text
_ARROW = 2.5  # arrow head length, mm

# Regions of the sheet (x0, y0, x1, y1), mm
_FRAME = (10.0, 10.0, 287.0, 200.0)
_VIEWS = (16.0, 16.0, 196.0, 134.0)
_ISO = (204.0, 22.0, 281.0, 104.0)
_TABLE = (16.0, 142.0, 190.0, 194.0)
_TITLE = (196.0, 112.0, 281.0, 194.0)


@dataclass(frozen=True)
class Line:
    x1: float
    y1: float
    x2: float
    y2: float
    width: float = THIN


@dataclass(frozen=True)
class Polygon:
    points: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Text:
    """`anchor`: where (x, y), the baseline's point, is on the text: start, middle or end;
    `angle`: degrees counter-clockwise (90: read from below)."""

    x: float
    y: float
    text: str
    size: float = TEXT_MM
    anchor: str = "start"
    angle: float = 0.0
    bold: bool = False
    colour: str = "#000000"


VERDICT_COLOURS = {"pass": "#1b7a2e", "fail": "#c62828", "uncertain": "#b26a00"}
"""The verdicts' colours (green, red, amber), beside their words."""


def _colour(verdict: str | None) -> str:
    return VERDICT_COLOURS.get(verdict or "", "#000000")


@dataclass
class Sheet:
    width: float
    height: float
    title: str
    lines: list[Line] = field(default_factory=list)
    polygons: list[Polygon] = field(default_factory=list)
    texts: list[Text] = field(default_factory=list)

    def rect(self, x0: float, y0: float, x1: float, y1: float, width: float = THIN) -> None:
        self.lines += [Line(x0, y0, x1, y0, width), Line(x1, y0, x1, y1, width),
                       Line(x1, y1, x0, y1, width), Line(x0, y1, x0, y0, width)]


def drawing_scale(size: tuple[float, float, float]) -> float:
    """The largest standard scale at which the three views and their dimensions fit the sheet."""
    w, h, d = size
    room_w = (_VIEWS[2] - _VIEWS[0]) - 2 * _GAP
    room_h = (_VIEWS[3] - _VIEWS[1]) - 2 * _GAP
    fit = min(room_w / (w + d), room_h / (h + d))
    return next((s for s in DRAWING_SCALES if s <= fit), DRAWING_SCALES[-1])


def scale_text(scale: float) -> str:
    """``2:1``, ``1:1``, ``1:5``."""
    if scale >= 1:
        return f"{scale:g}:1"
    return f"1:{1 / scale:g}"


def isometric(size: tuple[float, float, float]) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The edges the isometric view shows (front, top and right faces), in projected mm (y up):
    the box's X (width) to the lower right, Z (depth) to the upper right, the height up."""
    w, h, d = size
    c30, s30 = math.cos(math.radians(30)), math.sin(math.radians(30))

    def p(x: float, y: float, z: float) -> tuple[float, float]:  # y: up from the bottom
        return ((x + z) * c30, y + (z - x) * s30)

    corners = {(i, j, k): p(w * i, h * j, d * k) for i in (0, 1) for j in (0, 1) for k in (0, 1)}
    hidden = (0, 0, 1)  # the back lower left corner: its three edges are hidden
    edges = []
    for a in corners:
        for axis in range(3):
            if a[axis] == 0:
                b = tuple(1 if i == axis else v for i, v in enumerate(a))
                if hidden not in (a, b):
                    edges.append((corners[a], corners[b]))  # type: ignore[index]
    return edges


def inspection_sheet(part: Part, when: datetime) -> Sheet:
    """The sheet of `part` (see the module), dated `when`."""
    w, h, d = part.size
    scale = drawing_scale(part.size)
    sheet = Sheet(*SHEET_SIZE, title=f"Inspection sheet: {part.photo}")
    sheet.rect(*_FRAME, width=THICK)
    W, H, D = w * scale, h * scale, d * scale
    # The views' block centred in its region: [H dim][front][gap][side] across, [top][gap][front][W dim] down
    block_w, block_h = _GAP + W + _GAP + D, D + _GAP + H + _GAP
    x0 = _VIEWS[0] + _GAP + ((_VIEWS[2] - _VIEWS[0]) - block_w) / 2
    y_top = _VIEWS[1] + ((_VIEWS[3] - _VIEWS[1]) - block_h) / 2
    y_front = y_top + D + _GAP
    x_side = x0 + W + _GAP
    views = {"FRONT": (x0, y_front, W, H), "TOP": (x0, y_top, W, D), "RIGHT SIDE": (x_side, y_front, D, H)}
    for label, (x, y, vw, vh) in views.items():
        sheet.rect(x, y, x + vw, y + vh, THICK)
        sheet.texts.append(Text(x + vw / 2, y - 2.0 if label == "TOP" else y + vh + 18.0, label, 2.5,
                                "middle", bold=True))
    # Centre lines of the top view's depth and front view's height would add nothing on a box.
    _dimension(sheet, (x0, y_front + H), (x0 + W, y_front + H), 8.0, part.dimension("width"))
    _dimension(sheet, (x0, y_front), (x0, y_front + H), 8.0, part.dimension("height"))
    _dimension(sheet, (x_side, y_front + H), (x_side + D, y_front + H), 8.0, part.dimension("depth"))
    _isometric_view(sheet, part.size)
    _table(sheet, part)
    _title_block(sheet, part, when, scale)
    return sheet


def _dimension(sheet: Sheet, a: tuple[float, float], b: tuple[float, float], offset: float,
               dim: Dimension) -> None:
    """A dimension of the edge a -> b, drawn `offset` mm to its right-hand side (seen from a to b,
    y down): extension lines, the dimension line with arrows, its text beside it."""
    text, colour = dimension_text(dim), _colour(dim.verdict)
    (ax, ay), (bx, by) = a, b
    length = math.hypot(bx - ax, by - ay)
    ux, uy = (bx - ax) / length, (by - ay) / length
    nx, ny = -uy, ux  # the right-hand normal with y down: a bottom edge's points down
    pa = (ax + nx * offset, ay + ny * offset)
    pb = (bx + nx * offset, by + ny * offset)
    for (ex, ey), (px, py) in ((a, pa), (b, pb)):
        sheet.lines.append(Line(ex + nx * 1.0, ey + ny * 1.0, px + nx * 1.5, py + ny * 1.5))
    sheet.lines.append(Line(*pa, *pb))
    for (px, py), sign in ((pa, 1.0), (pb, -1.0)):
        tip_x, tip_y = px, py
        back_x, back_y = px + sign * ux * _ARROW, py + sign * uy * _ARROW
        sheet.polygons.append(Polygon(((tip_x, tip_y), (back_x + nx * 0.6, back_y + ny * 0.6),
                                       (back_x - nx * 0.6, back_y - ny * 0.6))))
    mx, my = (pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2
    if abs(uy) > abs(ux):  # a vertical dimension: text along it, read from the right
        sheet.texts.append(Text(mx - 1.0, my, text, anchor="middle", angle=90.0, colour=colour))
    else:  # text below a bottom dimension line
        sheet.texts.append(Text(mx, my + TEXT_MM + 1.0, text, anchor="middle", colour=colour))


def _isometric_view(sheet: Sheet, size: tuple[float, float, float]) -> None:
    edges = isometric(size)
    xs = [x for e in edges for x, _ in e]
    ys = [y for e in edges for _, y in e]
    x0, y0, x1, y1 = _ISO
    s = min((x1 - x0) / (max(xs) - min(xs)), (y1 - y0 - 8.0) / (max(ys) - min(ys)))
    ox = x0 + ((x1 - x0) - s * (max(xs) - min(xs))) / 2 - s * min(xs)
    oy = y1 - 8.0 - ((y1 - y0 - 8.0) - s * (max(ys) - min(ys))) / 2 + s * min(ys)
    for (ax, ay), (bx, by) in edges:
        sheet.lines.append(Line(ox + s * ax, oy - s * ay, ox + s * bx, oy - s * by, THICK))
    sheet.texts.append(Text((x0 + x1) / 2, y1, "ISOMETRIC (not to scale)", 2.5, "middle", bold=True))


def _number(v: float | None, signed: bool = False) -> str:
    if v is None:
        return "-"
    return f"{v:+.3f}" if signed else f"{v:.3f}"


def _table(sheet: Sheet, part: Part) -> None:
    x0, y0, x1, _ = _TABLE
    heads = ("dimension", "axis", "measured", "± 1 s.d.", "nominal", "tolerance ±", "deviation", "verdict")
    cols = (x0, x0 + 24, x0 + 36, x0 + 60, x0 + 82, x0 + 104, x0 + 128, x0 + 152)
    row_h = 7.0
    sheet.lines.append(Line(x0, y0, x1, y0, THICK))
    sheet.texts += [Text(cx + 1.0, y0 + 5.0, head, 2.6, bold=True)
                    for cx, head in zip(cols, heads, strict=True)]
    y = y0 + row_h
    sheet.lines.append(Line(x0, y, x1, y))
    for dim in part.dimensions:
        cells = (dim.name, dim.axis, _number(dim.value_mm), _number(dim.sigma_mm), _number(dim.nominal_mm),
                 _number(dim.tolerance_mm), _number(dim.deviation_mm, signed=True), dim.verdict or "-")
        sheet.texts += [Text(cx + 1.0, y + 5.0, cell, 2.8, bold=i == 7, colour=_colour(dim.verdict) if i == 7
                             else "#000000") for i, (cx, cell) in enumerate(zip(cols, cells, strict=True))]
        y += row_h
        sheet.lines.append(Line(x0, y, x1, y))
    verdict = part.verdict.upper() if part.verdict else "none (no nominal size given)"
    sheet.texts.append(Text(x0 + 1.0, y + 6.0, f"Part verdict: {verdict}", 3.5, bold=True,
                            colour=_colour(part.verdict)))
    k = f"k = {part.k:g}" if part.k is not None else "k = 2"
    sheet.texts.append(Text(x0 + 1.0, y + 12.0, "mm; ± is one standard deviation; a dimension passes when "
                            f"its deviation ± {k} sigma lies within the tolerance, fails when wholly "
                            "outside, else uncertain", 2.3))
    sheet.lines += [Line(cx, y0, cx, y0 + 4 * row_h) for cx in (*cols, x1)]


def _title_block(sheet: Sheet, part: Part, when: datetime, scale: float) -> None:
    x0, y0, x1, y1 = _TITLE
    sheet.rect(x0, y0, x1, y1, THICK)
    rows = [
        ("PrismCloud inspection sheet", ""),
        ("photo", part.photo),
        ("date", when.strftime("%Y-%m-%d %H:%M %Z").strip()),
        ("scale source", part.scale_source),
        ("drawing scale", f"{scale_text(scale)} on A4 (third-angle projection)"),
        ("units", "mm"),
        ("frame", _short_frame(part)),
        ("engine", f"PrismCloud {part.engine_version}".strip()),
    ]
    y = y0 + 7.0
    for i, (key, value) in enumerate(rows):
        if i == 0:
            sheet.texts.append(Text(x0 + 2.0, y, key, 3.5, bold=True))
        else:
            sheet.texts.append(Text(x0 + 2.0, y, key, 2.3, bold=True))
            for j, chunk in enumerate(_wrap(value, 44)):
                sheet.texts.append(Text(x0 + 2.0, y + 3.5 + 3.2 * j, chunk, 2.6))
            y += 3.2 * (len(_wrap(value, 44)) - 1) + 3.5
        y += 5.5
        if y < y1:
            sheet.lines.append(Line(x0, y - 3.8, x1, y - 3.8))


def _short_frame(part: Part) -> str:
    if part.frame == "box":
        return "box frame of the cloud: P1 at the origin, X width, Y down the front, Z depth"
    return part.frame_text.split(":", 1)[0] + ", " + part.frame_text.split(": ", 1)[-1]


def _wrap(text: str, width: int) -> list[str]:
    lines: list[str] = []
    for word in text.split():
        if lines and len(lines[-1]) + 1 + len(word) <= width:
            lines[-1] += " " + word
        else:
            lines.append(word)
    return lines or [""]

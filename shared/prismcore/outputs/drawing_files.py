"""The inspection sheet's files: SVG and PDF of the laid-out sheet (`prismcore.outputs.drawing`),
and DXF for CAD users, drawn from the part at true size (1 unit = 1 mm) with real DIMENSION
entities (ezdxf), whose texts are the sheet's (`part.dimension_text`).

Each returns the file's bytes; nothing is written here.

* SVG: ``width``/``height`` in mm, ``viewBox`` in sheet mm; texts as ``<text>`` (UTF-8, ± as is).
* PDF: one A4 landscape page (fpdf2, the core font Helvetica, Latin-1: ± is in it).
* DXF: R2013, units mm; layers OUTLINE (the views), DIMENSIONS, TEXT (the table and title); the
  front view with its lower left corner at (0, 0) and y up, the top view above it, the right
  side view to its right, the isometric view beyond; each dimension's measurement is the true
  length (`Dimension.get_measurement()` equals the report's value).
"""

from __future__ import annotations

import io
import math
from datetime import datetime
from xml.etree import ElementTree as ET

from prismcore.outputs.drawing import Sheet, Text, inspection_sheet, isometric
from prismcore.outputs.part import Part, dimension_text

__all__ = ["drawing_dxf", "drawing_pdf", "drawing_svg", "sheet_pdf", "sheet_svg"]

_PT_PER_MM = 72 / 25.4


def drawing_svg(part: Part, when: datetime) -> bytes:
    return sheet_svg(inspection_sheet(part, when))


def drawing_pdf(part: Part, when: datetime) -> bytes:
    return sheet_pdf(inspection_sheet(part, when), when)


def _n(v: float) -> str:
    return f"{v:.3f}".rstrip("0").rstrip(".")


def sheet_svg(sheet: Sheet) -> bytes:
    """The sheet as an SVG 1.1 document (mm)."""
    svg = ET.Element("svg", {"xmlns": "http://www.w3.org/2000/svg", "version": "1.1",
                             "width": f"{_n(sheet.width)}mm", "height": f"{_n(sheet.height)}mm",
                             "viewBox": f"0 0 {_n(sheet.width)} {_n(sheet.height)}"})
    ET.SubElement(svg, "title").text = sheet.title
    ET.SubElement(svg, "rect", {"x": "0", "y": "0", "width": _n(sheet.width), "height": _n(sheet.height),
                                "fill": "white"})
    lines = ET.SubElement(svg, "g", {"stroke": "black", "stroke-linecap": "round", "fill": "none"})
    for ln in sheet.lines:
        ET.SubElement(lines, "line", {"x1": _n(ln.x1), "y1": _n(ln.y1), "x2": _n(ln.x2), "y2": _n(ln.y2),
                                      "stroke-width": _n(ln.width)})
    arrows = ET.SubElement(svg, "g", {"fill": "black", "stroke": "none"})
    for poly in sheet.polygons:
        ET.SubElement(arrows, "polygon", {"points": " ".join(f"{_n(x)},{_n(y)}" for x, y in poly.points)})
    texts = ET.SubElement(svg, "g", {"font-family": "Helvetica, Arial, sans-serif", "fill": "black"})
    anchors = {"start": "start", "middle": "middle", "end": "end"}
    for t in sheet.texts:
        attrs = {"x": _n(t.x), "y": _n(t.y), "font-size": _n(t.size), "text-anchor": anchors[t.anchor]}
        if t.colour != "#000000":
            attrs["fill"] = t.colour
        if t.bold:
            attrs["font-weight"] = "bold"
        if t.angle:
            attrs["transform"] = f"rotate({_n(-t.angle)} {_n(t.x)} {_n(t.y)})"
        ET.SubElement(texts, "text", attrs).text = t.text
    ET.indent(svg)
    body: bytes = ET.tostring(svg, encoding="utf-8")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + body + b"\n"


def sheet_pdf(sheet: Sheet, when: datetime) -> bytes:
    """The sheet as a one-page PDF (fpdf2), its creation date `when`."""
    from fpdf import FPDF

    pdf = FPDF(orientation="L" if sheet.width > sheet.height else "P", unit="mm",
               format=(min(sheet.width, sheet.height), max(sheet.width, sheet.height)))
    pdf.set_auto_page_break(False)
    pdf.set_margin(0)
    pdf.set_title(sheet.title)
    pdf.set_creator("PrismCloud")
    pdf.set_creation_date(when)
    pdf.add_page()
    pdf.set_draw_color(0)
    pdf.set_fill_color(0)
    for ln in sheet.lines:
        pdf.set_line_width(ln.width)
        pdf.line(ln.x1, ln.y1, ln.x2, ln.y2)
    for poly in sheet.polygons:
        pdf.polygon(list(poly.points), style="F")
    for t in sheet.texts:
        _pdf_text(pdf, t)
    return bytes(pdf.output())


def _pdf_text(pdf: object, t: Text) -> None:
    from fpdf import FPDF

    assert isinstance(pdf, FPDF)
    pdf.set_font("Helvetica", "B" if t.bold else "", t.size * _PT_PER_MM)
    pdf.set_text_color(*(int(t.colour[i:i + 2], 16) for i in (1, 3, 5)))
    width = pdf.get_string_width(t.text)
    shift = {"start": 0.0, "middle": width / 2, "end": width}[t.anchor]
    if t.angle:
        with pdf.rotation(t.angle, t.x, t.y):
            pdf.text(t.x - shift, t.y, t.text)
    else:
        pdf.text(t.x - shift, t.y, t.text)


def drawing_dxf(part: Part, when: datetime) -> bytes:
    """The drawing as DXF R2013 at true size (see the module)."""
    from ezdxf import units
    from ezdxf.enums import TextEntityAlignment
    from ezdxf.filemanagement import new

    doc = new("R2013", setup=True)
    doc.units = units.MM
    doc.header["$MEASUREMENT"] = 1  # metric
    doc.header["$TDCREATE"] = _julian(when)
    for name, colour in (("OUTLINE", 7), ("DIMENSIONS", 1), ("TEXT", 7)):
        doc.layers.add(name, color=colour)
    msp = doc.modelspace()
    w, h, d = part.size
    gap = max(w, h, d) * 0.4 + 20.0
    text_h = max(w, h, d) / 40.0 + 1.5
    outline = {"layer": "OUTLINE", "lineweight": 50}
    for x, y, vw, vh in ((0.0, 0.0, w, h), (0.0, h + gap, w, d), (w + gap, 0.0, d, h)):
        msp.add_lwpolyline([(x, y), (x + vw, y), (x + vw, y + vh), (x, y + vh)], close=True,
                           dxfattribs=outline)
    labels = (("FRONT", w / 2, -gap * 0.75), ("TOP", w / 2, h + gap + d + text_h),
              ("RIGHT SIDE", w + gap + d / 2, -gap * 0.75))
    for label, x, y in labels:
        msp.add_text(label, height=text_h, dxfattribs={"layer": "TEXT"}).set_placement(
            (x, y), align=TextEntityAlignment.BOTTOM_CENTER)
    style = {"layer": "DIMENSIONS"}
    override = {"dimtxt": text_h, "dimasz": text_h, "dimexe": text_h / 2, "dimexo": text_h / 2, "dimdec": 3}
    off = gap * 0.35
    for base, p1, p2, angle, dim in (((0.0, -off), (0.0, 0.0), (w, 0.0), 0.0, "width"),
                                     ((-off, 0.0), (0.0, 0.0), (0.0, h), 90.0, "height"),
                                     ((w + gap, -off), (w + gap, 0.0), (w + gap + d, 0.0), 0.0, "depth")):
        msp.add_linear_dim(base=base, p1=p1, p2=p2, angle=angle, text=dimension_text(part.dimension(dim)),
                           dimstyle="EZDXF", override=override, dxfattribs=style).render()
    iso_x = w + gap + d + gap + math.cos(math.radians(30)) * w
    for (ax, ay), (bx, by) in isometric(part.size):
        msp.add_line((iso_x + ax, ay), (iso_x + bx, by), dxfattribs=outline)
    lines = [f"PrismCloud inspection: {part.photo}", f"date {when.strftime('%Y-%m-%d %H:%M %Z').strip()}",
             f"scale source: {part.scale_source}", "units mm, 1:1; ± is one standard deviation",
             f"part verdict: {part.verdict or 'none (no nominal size given)'}"]
    lines += [f"{x.name}: {dimension_text(x)}" for x in part.dimensions]
    top = h + gap + d + gap
    for i, line in enumerate(lines):
        msp.add_text(line, height=text_h, dxfattribs={"layer": "TEXT"}).set_placement(
            (0.0, top + (len(lines) - i) * text_h * 1.6))
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode("utf-8")


def _julian(when: datetime) -> float:
    """A DXF date: the Julian day and its fraction."""
    return when.timestamp() / 86400.0 + 2440587.5

"""The part as CAD files, on a rendered box of known size: the STEP solid read back by OpenCascade
(one closed solid, six faces, its bounds and volume the reported dimensions, its properties), the
DXF audited and its dimensions read by ezdxf, the SVG parsed as XML and the PDF's text read by
pypdf, each carrying the report's numbers; a scan without a scale refused."""

from __future__ import annotations

import json
import math
import re
import sys
from datetime import UTC, datetime
from pathlib import Path
from xml.etree import ElementTree as ET

import ezdxf
import pytest
from pydantic import ValidationError
from pypdf import PdfReader

from prismcore import InputError, ScanSpec, run_scan
from prismcore.outputs.part import dimension_text, part_from_report
from prismcore.outputs.writers import write_format
from prismcore.report import report_dict
from prismcore.spec import FILE_NAMES, output_files
from prismsynth import Box, render_oblique_view

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
SCENE = render_oblique_view(BOX, seed=5)
WHEN = datetime(2026, 12, 6, 14, 30, tzinfo=UTC)
DIMS = ("width", "height", "depth")
_NUMBER = re.compile(r"^(\d+\.\d{3}) ± (\d+\.\d{3}) (pass|fail|uncertain)$")


def _spec(**extra) -> ScanSpec:
    return ScanSpec.model_validate({"image": "parts/box.png", "points": [SCENE.points[n] for n in NAMES],
                                    "focal_px": 1400.0, "nominal": [120, 80, 60], "tolerance_mm": 0.5,
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0},
                                    "formats": ["step", "drawing"], **extra})


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> tuple[dict, dict[str, Path]]:
    spec = _spec()
    result = run_scan(spec, SCENE.image)
    out = tmp_path_factory.mktemp("cad")
    paths = {}
    for kind in output_files(spec.formats):
        paths[kind] = out / FILE_NAMES[kind]
        write_format(kind, paths[kind], result.cloud, spec, report=result.report, images=[SCENE.image],
                     when=WHEN)
    return report_dict(result.report), paths  # report.json's content


def _read_step(path: Path):
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_RetDone
    assert reader.TransferRoots() >= 1
    return reader.OneShape()


def _count(shape, kind) -> list:
    from OCP.TopExp import TopExp_Explorer

    found, explorer = [], TopExp_Explorer(shape, kind)
    while explorer.More():
        found.append(explorer.Current())
        explorer.Next()
    return found


def _bounds(shape) -> tuple[float, ...]:
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)  # exact: no tolerance enlargement
    lo, hi = box.CornerMin(), box.CornerMax()
    return (lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z())


def _volume(shape) -> float:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return props.Mass()


def _size(report: dict) -> tuple[float, float, float]:
    return tuple(float(report["dimensions"][d]) for d in DIMS)


def test_the_files_are_the_formats_files(written):
    _, paths = written
    assert {p.name for p in paths.values()} == {"part.step", "part.step.json", "drawing.svg", "drawing.pdf",
                                               "drawing.dxf"}
    assert all(p.stat().st_size > 0 for p in paths.values())


def test_the_step_file_is_one_closed_solid_of_the_reported_size(written):
    from OCP.BRep import BRep_Tool
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID

    report, paths = written
    text = paths["step"].read_text()
    assert "AP242_MANAGED_MODEL_BASED_3D_ENGINEERING_MIM_LF" in text and "SI_UNIT(.MILLI.,.METRE.)" in text
    shape = _read_step(paths["step"])
    assert len(_count(shape, TopAbs_SOLID)) == 1
    assert len(_count(shape, TopAbs_FACE)) == 6
    shells = _count(shape, TopAbs_SHELL)
    assert len(shells) == 1 and BRep_Tool.IsClosed_s(shells[0])
    assert BRepCheck_Analyzer(shape).IsValid()
    w, h, d = _size(report)
    # the box frame of the cloud: P1 at the origin, X width, Y height (down the front), Z depth
    assert _bounds(shape) == pytest.approx((0.0, 0.0, 0.0, w, h, d), abs=1e-6)
    assert _volume(shape) == pytest.approx(w * h * d, rel=1e-9)


def test_the_step_file_holds_the_dimensions_sigmas_and_verdicts(written):
    from OCP.collections import Sequence_TDF_Label
    from OCP.STEPCAFControl import STEPCAFControl_Reader
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_NamedData
    from OCP.TDocStd import TDocStd_Document
    from OCP.XCAFApp import XCAFApp_Application
    from OCP.XCAFDoc import XCAFDoc_DocumentTool

    report, paths = written
    doc = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    XCAFApp_Application.GetApplication_s().InitDocument(doc)
    reader = STEPCAFControl_Reader()
    reader.SetMetaMode(True)
    reader.ReadFile(str(paths["step"]))
    assert reader.Transfer(doc)
    labels = Sequence_TDF_Label()
    XCAFDoc_DocumentTool.ShapeTool_s(doc.Main()).GetFreeShapes(labels)
    assert labels.Length() == 1
    data = TDataStd_NamedData()
    assert labels.Value(1).FindAttribute(TDataStd_NamedData.GetID_s(), data)

    def real(name: str) -> float:
        return data.GetReal(TCollection_ExtendedString(name))

    def string(name: str) -> str:
        return data.GetString(TCollection_ExtendedString(name)).ToExtString()

    quality = report["quality"]["dimensions"]
    for d in DIMS:
        assert real(f"{d}_mm") == report["dimensions"][d]
        assert real(f"{d}_sigma_mm") == report["uncertainty"][d]
        assert real(f"{d}_nominal_mm") == quality[d]["nominal_mm"]
        assert real(f"{d}_deviation_mm") == quality[d]["deviation_mm"]
        assert string(f"{d}_verdict") == quality[d]["verdict"]
    assert string("verdict") == report["quality"]["verdict"]
    assert string("photo") == "box.png"
    # the sidecar says the same, for programs that do not read STEP properties
    meta = json.loads(paths["step_meta"].read_text())
    assert meta["unit"] == "mm" and meta["frame"] == "box" and meta["verdict"] == report["quality"]["verdict"]
    for d in DIMS:
        assert meta["dimensions"][d]["value_mm"] == report["dimensions"][d]
        assert meta["dimensions"][d]["sigma_mm"] == report["uncertainty"][d]
        assert meta["dimensions"][d]["verdict"] == quality[d]["verdict"]


def test_on_a_station_the_solid_stands_in_the_boards_frame(written, tmp_path):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Trsf

    report = json.loads(json.dumps(written[0]))
    report["station"] = {"position_mm": [140.5, 92.25], "yaw_deg": 33.0}
    report["scale_source"] = "station"
    path = tmp_path / "part.step"
    write_format("step", path, None, _spec(), report=report, when=WHEN)  # type: ignore[arg-type]
    shape = _read_step(path)
    w, h, d = _size(report)
    assert _volume(shape) == pytest.approx(w * h * d, rel=1e-9)
    x0, y0, z0, x1, y1, z1 = _bounds(shape)
    assert ((x0 + x1) / 2, (y0 + y1) / 2) == pytest.approx((140.5, 92.25), abs=1e-6)  # footprint centre
    assert (z0, z1) == pytest.approx((-h, 0.0), abs=1e-6)  # on the support, z into it
    # undo the yaw about the footprint's centre: the box's own extents, width along x
    back = gp_Trsf()
    a = math.radians(-33.0)
    back.SetValues(math.cos(a), -math.sin(a), 0, -140.5 * math.cos(a) + 92.25 * math.sin(a),
                   math.sin(a), math.cos(a), 0, -140.5 * math.sin(a) - 92.25 * math.cos(a), 0, 0, 1, 0)
    local = BRepBuilderAPI_Transform(shape, back, True).Shape()
    assert _bounds(local) == pytest.approx((-w / 2, -d / 2, -h, w / 2, d / 2, 0.0), abs=1e-6)


def test_the_dxf_passes_audit_and_its_dimensions_are_the_reports(written):
    report, paths = written
    doc = ezdxf.readfile(paths["drawing_dxf"])
    auditor = doc.audit()
    assert not auditor.has_errors, [e.message for e in auditor.errors]
    assert doc.units == ezdxf.units.MM
    dims = doc.modelspace().query("DIMENSION")
    assert len(dims) == 3
    part = part_from_report(report)
    texts = [dim.dxf.text for dim in dims]
    assert texts == [dimension_text(part.dimension(d)) for d in DIMS]
    for dim, d in zip(dims, DIMS, strict=True):
        value, sigma, verdict = _NUMBER.match(dim.dxf.text).groups()
        assert float(value) == round(report["dimensions"][d], 3)
        assert float(sigma) == round(report["uncertainty"][d], 3)
        assert verdict == report["quality"]["dimensions"][d]["verdict"]
        assert dim.get_measurement() == pytest.approx(report["dimensions"][d], abs=1e-9)  # drawn 1:1


def _sheet_numbers(texts: list[str], report: dict) -> None:
    """The texts carry each dimension as `value ± sigma verdict`, the photo, the date, the scale's
    source and the part's verdict."""
    joined = "\n".join(texts)
    for d in DIMS:
        shown = f"{report['dimensions'][d]:.3f} ± {report['uncertainty'][d]:.3f} "
        shown += report["quality"]["dimensions"][d]["verdict"]
        assert shown in joined, (d, shown, joined)
    assert "box.png" in joined and "2026-12-06 14:30" in joined
    assert "known edge: width = 120.0 mm" in joined
    assert f"Part verdict: {report['quality']['verdict'].upper()}" in joined
    for view in ("FRONT", "TOP", "RIGHT SIDE", "ISOMETRIC"):
        assert view in joined


def test_the_svg_carries_the_reports_numbers(written):
    report, paths = written
    root = ET.parse(paths["drawing_svg"]).getroot()
    ns = "{http://www.w3.org/2000/svg}"
    assert root.tag == f"{ns}svg" and root.get("width") == "297mm" and root.get("height") == "210mm"
    texts = [t.text or "" for t in root.iter(f"{ns}text")]
    _sheet_numbers(texts, report)


def test_the_pdf_carries_the_reports_numbers(written):
    report, paths = written
    pdf = PdfReader(paths["drawing_pdf"])
    assert len(pdf.pages) == 1
    box = pdf.pages[0].mediabox
    assert (round(float(box.width) * 25.4 / 72), round(float(box.height) * 25.4 / 72)) == (297, 210)
    _sheet_numbers(pdf.pages[0].extract_text().splitlines(), report)


def test_a_scan_without_a_scale_is_refused_step_and_drawing(written, tmp_path):
    for fmt in ("step", "drawing"):
        with pytest.raises(ValidationError, match=f"format '{fmt}' is in mm or metres, but without a scale"):
            ScanSpec.model_validate({"image": "box.png", "points": [SCENE.points[n] for n in NAMES],
                                     "formats": [fmt]})
    report = json.loads(json.dumps(written[0]))
    report["dimensions"]["unit"] = "px"
    with pytest.raises(InputError, match=r"the step format need the dimensions in mm.*pixels means nothing"):
        write_format("step", tmp_path / "part.step", None, _spec(), report=report)  # type: ignore[arg-type]
    assert not (tmp_path / "part.step").exists()


def test_without_the_cad_extra_step_says_which_extra(monkeypatch, written, tmp_path):
    monkeypatch.setitem(sys.modules, "OCP.BRepBuilderAPI", None)  # as if OCP were not installed
    with pytest.raises(InputError, match=r"pip install 'prismcloud\[cad\]'"):
        write_format("step", tmp_path / "part.step", None, _spec(), report=written[0])  # type: ignore[arg-type]

"""The part as a STEP solid (AP242), written by OpenCascade (OCP, the optional extra ``cad``).

One closed solid: OpenCascade's box ``[0, W] x [0, H] x [0, D]`` mm (six planar faces), carried
into the measurement's frame by `Part.placement` (`prismcore.outputs.part`: the cloud's box frame
for a photo, the board's frame on a station). Units are millimetres.

Inside the file (STEP AP242's user-defined attributes, which CAD and PLM programs list as the
part's properties): for each dimension its value, one-sigma and axis, and with a nominal its
nominal, tolerance, deviation and verdict; the part's verdict, the frame, the photo, the scale's
source. The header's description says the same in one line. `step_metadata` is the same content
for the JSON sidecar (``part.step.json``), for programs that do not read STEP properties.

The kernel is imported on first use: without the extra, asking for a STEP file says how to get it.
"""

from __future__ import annotations

import os
import tempfile
import threading
from datetime import datetime
from typing import Any

from prismcore.errors import InputError
from prismcore.outputs.part import Dimension, Part

__all__ = ["CAD_EXTRA_HINT", "step_bytes", "step_metadata"]

CAD_EXTRA_HINT = ("the step format needs the CAD kernel, the optional extra 'cad': "
                  "pip install 'prismcloud[cad]' (OpenCascade's OCP, cadquery-ocp-novtk)")

_LOCK = threading.Lock()  # OpenCascade's writer settings (Interface_Static) are process-wide


def step_metadata(part: Part) -> dict[str, Any]:
    """The solid's properties, as the STEP file holds them and the JSON sidecar gives them."""
    dims = {}
    for d in part.dimensions:
        entry: dict[str, Any] = {"value_mm": d.value_mm, "sigma_mm": d.sigma_mm, "axis": d.axis}
        if d.nominal_mm is not None:
            entry |= {"nominal_mm": d.nominal_mm, "tolerance_mm": d.tolerance_mm,
                      "deviation_mm": d.deviation_mm, "verdict": d.verdict}
        dims[d.name] = entry
    return {
        "unit": "mm",
        "dimensions": dims,
        "sigma": "one standard deviation",
        "verdict": part.verdict,
        "verdict_k": part.k,
        "frame": part.frame,
        "frame_text": part.frame_text,
        "placement": [list(row) for row in part.placement],
        "solid": "the box [0, W] x [0, H] x [0, D] in its own frame (X width, Y height, Z depth), "
                 "placed by `placement` ([R | t], x' = R x + t)",
        "photo": part.photo,
        "scale_source": part.scale_source,
        "engine_version": part.engine_version,
    }


def _attributes(part: Part) -> list[tuple[str, float | str]]:
    """(name, value) of each STEP user-defined attribute: numbers as reals, words as strings."""
    out: list[tuple[str, float | str]] = []
    for d in part.dimensions:
        out.append((f"{d.name}_mm", d.value_mm))
        if d.sigma_mm is not None:
            out.append((f"{d.name}_sigma_mm", d.sigma_mm))
        for key, value in (("nominal_mm", d.nominal_mm), ("tolerance_mm", d.tolerance_mm),
                           ("deviation_mm", d.deviation_mm), ("verdict", d.verdict)):
            if value is not None:
                out.append((f"{d.name}_{key}", value))
    if part.verdict is not None:
        out.append(("verdict", part.verdict))
    out += [("sigma", "one standard deviation"), ("frame", part.frame), ("photo", part.photo),
            ("scale_source", part.scale_source)]
    return out


def step_bytes(part: Part, when: datetime) -> bytes:
    """The STEP AP242 file of `part`'s solid (see the module), time-stamped `when`.

    Raises
    ------
    InputError
        OCP (the extra ``cad``) is not installed, or OpenCascade could not write the solid.
    """
    try:
        from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
        from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
        from OCP.gp import gp_Pnt, gp_Trsf
        from OCP.Message import Message
        from OCP.STEPCAFControl import STEPCAFControl_Writer
        from OCP.STEPControl import STEPControl_AsIs, STEPControl_Controller
        from OCP.TCollection import TCollection_ExtendedString, TCollection_HAsciiString
        from OCP.TDataStd import TDataStd_Name, TDataStd_NamedData
        from OCP.TDocStd import TDocStd_Document
        from OCP.XCAFApp import XCAFApp_Application
        from OCP.XCAFDoc import XCAFDoc_DocumentTool
    except ImportError:
        raise InputError(CAD_EXTRA_HINT) from None
    from OCP.APIHeaderSection import APIHeaderSection_MakeHeader
    from OCP.Interface import Interface_Static

    w, h, d = part.size
    shape = BRepPrimAPI_MakeBox(gp_Pnt(0.0, 0.0, 0.0), w, h, d).Shape()
    m = part.placement
    if m != ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)):
        trsf = gp_Trsf()
        trsf.SetValues(*m[0], *m[1], *m[2])
        shape = BRepBuilderAPI_Transform(shape, trsf, True).Shape()

    def text(s: str) -> Any:  # an OCP TCollection_ExtendedString
        return TCollection_ExtendedString(s, True)  # True: the string is UTF-8

    with _LOCK:
        messenger = Message.DefaultMessenger_s()
        for printer in list(messenger.Printers()):  # OpenCascade prints its statistics otherwise
            messenger.RemovePrinter(printer)
        STEPControl_Controller.Init_s()
        Interface_Static.SetCVal_s("write.step.schema", "AP242DIS")
        Interface_Static.SetCVal_s("write.step.unit", "MM")
        Interface_Static.SetCVal_s("write.step.product.name", "measured part")
        doc = TDocStd_Document(text("XmlXCAF"))
        XCAFApp_Application.GetApplication_s().InitDocument(doc)
        label = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main()).AddShape(shape, False)
        TDataStd_Name.Set_s(label, text(f"measured part ({part.photo})"))
        data = TDataStd_NamedData.Set_s(label)
        for name, value in _attributes(part):
            if isinstance(value, str):
                data.SetString(text(name), text(value))
            else:
                data.SetReal(text(name), value)
        writer = STEPCAFControl_Writer()
        writer.SetNameMode(True)
        writer.SetMetadataMode(True)
        if not writer.Transfer(doc, STEPControl_AsIs):
            raise InputError("OpenCascade could not convert the box to STEP")
        header = APIHeaderSection_MakeHeader(writer.ChangeWriter().Model())
        summary = "; ".join(f"{x.name} {_value_text(x)} mm{' ' + x.verdict if x.verdict else ''}"
                            for x in part.dimensions)
        header.SetDescriptionValue(1, TCollection_HAsciiString(_ascii(
            f"PrismCloud measured part: {summary} (+- one standard deviation); verdict "
            f"{part.verdict or 'none'}; scale: {part.scale_source}; frame: {part.frame}")))
        header.SetName(TCollection_HAsciiString(_ascii(part.photo)))
        header.SetAuthorValue(1, TCollection_HAsciiString("PrismCloud"))
        header.SetOrganizationValue(1, TCollection_HAsciiString("PrismCloud"))
        header.SetOriginatingSystem(TCollection_HAsciiString(f"PrismCloud {part.engine_version}".strip()))
        header.SetTimeStamp(TCollection_HAsciiString(when.strftime("%Y-%m-%dT%H:%M:%S")))
        header.Apply(writer.ChangeWriter().Model())
        fd, path = tempfile.mkstemp(suffix=".step")
        os.close(fd)
        try:  # OpenCascade writes to a path only
            status = writer.Write(path)
            if "RetDone" not in str(status):
                raise InputError(f"OpenCascade could not write the STEP file ({status})")
            with open(path, "rb") as fh:
                return fh.read()
        finally:
            os.unlink(path)


def _ascii(s: str) -> str:
    """A STEP header string: ISO 10303-21 strings are ASCII here (no apostrophe, no ±)."""
    return s.replace("±", "+-").replace("'", "").encode("ascii", "replace").decode()


def _value_text(d: Dimension) -> str:
    return f"{d.value_mm:.3f}" + ("" if d.sigma_mm is None else f" +- {d.sigma_mm:.3f}")

"""The measured box as a binary STL mesh (format stl), on a rendered box of known size: read back by
trimesh, one closed, consistently wound mesh with outward normals whose extents and volume are the
reported dimensions, placed as the STEP solid is; put into a sink by write_outputs with its name
and media type from the format table; refused without a scale."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import pytest
import trimesh
from pydantic import ValidationError

from prismcore import ScanSpec, run_scan
from prismcore.outputs.part import part_from_report
from prismcore.outputs.sink import Writer, write_outputs
from prismcore.outputs.writers import write_part
from prismcore.report import report_dict
from prismsynth import Box, render_oblique_view

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
SCENE = render_oblique_view(BOX, seed=5)


class DictSink:
    """A sink that keeps each file's bytes and media type."""

    def __init__(self) -> None:
        self.files: dict[str, tuple[bytes, str]] = {}

    def put(self, name: str, data: bytes | Writer, media_type: str) -> None:
        if not isinstance(data, bytes):
            buffer = io.BytesIO()
            data(buffer)
            data = buffer.getvalue()
        self.files[name] = (data, media_type)


def _spec(**extra: Any) -> ScanSpec:
    return ScanSpec.model_validate({"image": "box.png", "points": [SCENE.points[n] for n in NAMES],
                                    "focal_px": 1400.0,
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0},
                                    "formats": ["stl"], **extra})


@pytest.fixture(scope="module")
def scanned() -> tuple[dict, DictSink]:
    spec = _spec()
    result = run_scan(spec, SCENE.image)
    sink = DictSink()
    write_outputs(result, sink, spec=spec, images=[SCENE.image])
    return report_dict(result.report), sink


def _mesh(data: bytes) -> trimesh.Trimesh:
    mesh = trimesh.load(io.BytesIO(data), file_type="stl")
    assert isinstance(mesh, trimesh.Trimesh)
    return mesh


def test_the_sink_gets_box_stl_as_model_stl(scanned):
    _, sink = scanned
    assert list(sink.files) == ["box.stl", "overlay.jpg", "report.json"]
    data, media = sink.files["box.stl"]
    assert media == "model/stl"
    assert len(data) == 84 + 12 * 50 and not data.startswith(b"solid")


def test_the_mesh_is_a_closed_box_of_the_reported_size(scanned):
    report, sink = scanned
    mesh = _mesh(sink.files["box.stl"][0])
    dims = report["dimensions"]
    size = np.array([dims["width"], dims["height"], dims["depth"]])
    assert len(mesh.faces) == 12
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(float(np.prod(size)), rel=1e-5)  # > 0: normals point out
    np.testing.assert_allclose(mesh.bounds, [np.zeros(3), size], atol=1e-4)  # the cloud's box frame
    np.testing.assert_allclose(mesh.face_normals, trimesh.triangles.normals(mesh.triangles)[0], atol=1e-6)


def test_on_a_station_the_mesh_stands_where_the_step_solid_does(scanned):
    report = {**scanned[0], "station": {"position_mm": [140.5, 92.25], "yaw_deg": 33.0},
              "scale_source": "station"}
    buffer = io.BytesIO()
    write_part("stl", buffer, report)
    mesh = _mesh(buffer.getvalue())
    part = part_from_report(report)
    placement = np.array(part.placement)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) * np.array(part.size)
    placed = corners @ placement[:, :3].T + placement[:, 3]
    assert mesh.is_watertight and mesh.volume == pytest.approx(float(np.prod(part.size)), rel=1e-5)
    np.testing.assert_allclose(np.sort(mesh.vertices, axis=0), np.sort(placed, axis=0), atol=1e-3)


def test_a_scan_without_a_scale_is_refused_stl():
    with pytest.raises(ValidationError, match="format 'stl'"):
        ScanSpec.model_validate({"image": "box.png", "points": [SCENE.points[n] for n in NAMES],
                                 "formats": ["stl"]})

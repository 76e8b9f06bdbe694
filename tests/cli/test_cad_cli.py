"""`prism scan --format step,drawing` as a user runs it: the part's STEP solid and inspection
drawing beside the report, from a photo (the cloud's box frame) and on a station (the station's
frame); without a scale, one line and exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import cv2
import ezdxf
import numpy as np
import pytest
from pypdf import PdfReader

from prismsynth.station import calibration_views, station_scene

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples"
JOB = json.loads((SAMPLE / "job.json").read_text())
POINTS = " ".join(f"{x},{y}" for x, y in JOB["points"].values())
SCALE = ("--focal-px", str(JOB["focal_px"]), "--distance-mm", str(JOB["scale"]["distance_mm"]))
PRISM = Path(sys.executable).with_name("prism")
FILES = ("part.step", "part.step.json", "drawing.svg", "drawing.pdf", "drawing.dxf")


def prism(*args: object, cwd: Path = SAMPLE) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(PRISM), *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd)


def _step_bounds(path: Path) -> tuple[float, ...]:
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    reader.ReadFile(str(path))
    reader.TransferRoots()
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(reader.OneShape(), box, False, False)
    lo, hi = box.CornerMin(), box.CornerMax()
    return (lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z())


def test_a_photo_scan_writes_the_solid_and_the_drawing(tmp_path):
    out = tmp_path / "out"
    run = prism("scan", "box.jpg", "--points", POINTS, *SCALE, "--nominal", "120,80,60",
                "--tolerance-mm", "2.5", "--format", "step,drawing", "--out", out)
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == sorted([*FILES, "overlay.jpg", "report.json"])
    for name in FILES:
        assert f": {out / name}" in run.stdout  # each file's path printed, as the clouds' are
    report = json.loads((out / "report.json").read_text())
    w, h, d = (report["dimensions"][k] for k in ("width", "height", "depth"))
    assert _step_bounds(out / "part.step") == pytest.approx((0, 0, 0, w, h, d), abs=1e-6)
    assert {"write_step", "write_drawing_pdf"} <= set(report["timings_ms"])
    shown = f"{w:.3f} ± {report['uncertainty']['width']:.3f} pass"
    svg = [t.text for t in ET.parse(out / "drawing.svg").getroot().iter("{http://www.w3.org/2000/svg}text")]
    assert shown in svg and "box.jpg" in svg
    assert shown in PdfReader(out / "drawing.pdf").pages[0].extract_text()
    dims = ezdxf.readfile(out / "drawing.dxf").modelspace().query("DIMENSION")
    assert shown in [dim.dxf.text for dim in dims]


@pytest.mark.parametrize("fmt", ["step", "drawing", "csv,step"])
def test_without_a_scale_step_and_drawing_exit_2_in_one_line(tmp_path, fmt):
    run = prism("scan", "box.jpg", "--points", POINTS, "--focal-px", "1400", "--format", fmt,
                "--out", tmp_path / "o")
    assert run.returncode == 2, run.stdout + run.stderr
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("prism: error:"), run.stderr
    assert "without a scale the dimensions are in pixels" in run.stderr and "format '" in run.stderr
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def _save(path: Path, rgb: np.ndarray) -> Path:
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def test_on_a_station_the_solid_stands_where_the_station_measured_it(tmp_path):
    sc = station_scene(4)
    _save(tmp_path / "plate.png", sc.plate)
    _save(tmp_path / "photo.jpg", sc.photo)
    views = calibration_views(sc.setup, 8, 1)
    calib = [_save(tmp_path / f"calib{i}.jpg", v).name for i, v in enumerate(views)]
    (tmp_path / "board.json").write_text(json.dumps(sc.setup.board.describe()))
    run = prism("station", "calibrate", "--board", "board.json", "--plane", "plate.png",
                "--plate", "plate.png", *calib, "--out", "station.json", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    run = prism("scan", "photo.jpg", "--station", "station.json", "--format", "step,drawing", "--out", "out",
                cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "out/report.json").read_text())
    x, y = report["station"]["position_mm"]
    x0, y0, z0, x1, y1, z1 = _step_bounds(tmp_path / "out/part.step")
    assert ((x0 + x1) / 2, (y0 + y1) / 2) == pytest.approx((x, y), abs=1e-6)
    assert (z0, z1) == pytest.approx((-report["dimensions"]["height"], 0.0), abs=1e-6)
    meta = json.loads((tmp_path / "out/part.step.json").read_text())
    assert meta["frame"] == "station" and meta["scale_source"].startswith("station")
    assert meta["dimensions"]["width"]["value_mm"] == report["dimensions"]["width"]
    svg = "\n".join(t.text or "" for t in ET.parse(tmp_path / "out/drawing.svg").getroot().iter(
        "{http://www.w3.org/2000/svg}text"))
    assert "station calibration" in svg and "photo.jpg" in svg


def test_photos_measured_as_one_box_write_the_solid_and_the_drawing_and_no_cloud(tmp_path):
    from prismsynth import photo_like_views, save_image

    scenes = photo_like_views(2, 2)
    points = []
    for k, p in enumerate(scenes):
        save_image(p.image, tmp_path / f"view{k + 1}.png")
        points.append([[float(p.clicks[f"p{i}"][0]), float(p.clicks[f"p{i}"][1])] for i in range(1, 8)])
    (tmp_path / "points.json").write_text(json.dumps(points))
    known = [f"--{scenes[0].known_edge}-mm", f"{scenes[0].known_length_mm:.4f}"]
    run = prism("scan", "view1.png", "view2.png", "--points-file", "points.json", *known,
                "--format", "step,drawing", "--out", "out", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted([*FILES, "joint.json"])
    joint = json.loads((tmp_path / "out/joint.json").read_text())
    w, h, d = (joint["dimensions"][k] for k in ("width", "height", "depth"))
    assert _step_bounds(tmp_path / "out/part.step") == pytest.approx((0, 0, 0, w, h, d), abs=1e-6)
    svg = [t.text or "" for t in ET.parse(tmp_path / "out/drawing.svg").getroot().iter(
        "{http://www.w3.org/2000/svg}text")]
    assert f"{h:.3f} ± {joint['uncertainty']['height']:.3f}" in svg  # no nominal: no verdict
    assert "2 views: view1.png, view2.png" in svg
    run = prism("scan", "view1.png", "view2.png", "--points-file", "points.json", *known,
                "--format", "laz,step", "--out", "bad", cwd=tmp_path)
    assert run.returncode == 2 and "make no cloud; --format takes step and drawing" in run.stderr, run.stderr

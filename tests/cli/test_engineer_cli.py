"""`prism scan` for engineers: verdicts against a nominal size, a cloud at a spacing, LAZ and glb."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
import trimesh

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples"
JOB = json.loads((SAMPLE / "job.json").read_text())
POINTS = " ".join(f"{x},{y}" for x, y in JOB["points"].values())
SCALE = ("--focal-px", str(JOB["focal_px"]), "--distance-mm", str(JOB["scale"]["distance_mm"]))


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=300, cwd=SAMPLE)


def test_verdicts_spacing_laz_and_glb_from_flags(tmp_path):
    out = tmp_path / "out"
    run = prism("scan", "box.jpg", "--points", POINTS, *SCALE, "--nominal", "120,80,60",
                "--tolerance-mm", "0.5,0.5,9", "--spacing-mm", "0.5", "--format", "laz,glb",
                "--out", str(out))
    assert run.returncode == 0, run.stderr
    report = json.loads((out / "report.json").read_text())
    quality = report["quality"]
    assert report["inputs"]["nominal"] == [120.0, 80.0, 60.0]
    assert report["inputs"]["tolerance_mm"] == [0.5, 0.5, 9.0]
    assert report["inputs"]["spacing_mm"] == 0.5
    assert quality["dimensions"]["depth"]["verdict"] == "pass"  # 60 ± 9 around a ~60 mm depth
    for name, row in quality["dimensions"].items():
        line = next(li for li in run.stdout.splitlines() if li.startswith(name))
        assert f"{row['measured_mm']:.2f} mm" in line and line.rstrip().endswith(row["verdict"])
    assert f"{quality['verdict'].upper()}  pass {quality['counts']['pass']}" in run.stdout
    assert not (out / "cloud.csv").exists() and not (out / "cloud.ply").exists()
    las = laspy.read(out / "cloud.laz")
    assert las.header.point_count == report["points"]
    assert report["points"] < 639_716 / 3  # thinned from one point per pixel
    scene = trimesh.load(out / "box.glb", force="scene")
    size = np.array([report["dimensions"][k] for k in ("width", "height", "depth")]) / 1000
    assert np.allclose(scene.extents, size, atol=1e-6)


def test_no_nominal_no_quality_lines(tmp_path):
    run = prism("scan", "--spec", "job.json", "--out", str(tmp_path / "o"))
    assert run.returncode == 0, run.stderr
    assert json.loads((tmp_path / "o" / "report.json").read_text())["quality"] is None
    assert " mm  nominal " not in run.stdout and "PASS" not in run.stdout


@pytest.mark.parametrize(("flags", "message"), [
    (("--nominal", "120,80", "--tolerance-mm", "1"), "--nominal '120,80': expected W,H,D in mm"),
    (("--nominal", "120,80,x", "--tolerance-mm", "1"), "--nominal '120,80,x': expected W,H,D in mm"),
    (("--nominal", "120,80,60", "--tolerance-mm", "1,2"), "'1,2': expected T or Tw,Th,Td in mm"),
    (("--nominal", "120,80,60", "--tolerance-mm", "-1"), "a tolerance is >= 0 mm"),
    (("--nominal", "120,0,60", "--tolerance-mm", "1"), "sizes are > 0 mm"),
    (("--nominal", "120,80,nan", "--tolerance-mm", "1"), "expected W,H,D in mm"),
    (("--tolerance-mm", "1"), "--nominal and --tolerance-mm go together"),
    (("--spacing-mm", "0"), "--spacing-mm must be > 0"),
    (("--format", "csv,obj"), "formats"),
])
def test_bad_values_exit_2_with_one_line(tmp_path, flags, message):
    run = prism("scan", "box.jpg", "--points", POINTS, *SCALE, *flags, "--out", str(tmp_path / "o"))
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("prism: error:")
    assert message in run.stderr
    assert not (tmp_path / "o").exists()


def test_metric_outputs_need_a_scale_and_flags_do_not_mix_with_a_spec(tmp_path):
    run = prism("scan", "box.jpg", "--points", POINTS, "--format", "glb", "--out", str(tmp_path / "o"))
    assert run.returncode == 2 and "without a scale" in run.stderr
    run = prism("scan", "--spec", "job.json", "--nominal", "1,2,3", "--tolerance-mm", "1",
                "--out", str(tmp_path / "o"))
    assert run.returncode == 2 and "in a spec file, set nominal" in run.stderr

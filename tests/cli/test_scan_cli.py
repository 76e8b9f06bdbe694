"""`prism scan` end to end in a subprocess: outputs on success, one line and exit 2 on bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from plyfile import PlyData

POINTS = "61,51 258,49 261,249 262,50 339,52"


def prism(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


@pytest.fixture(scope="module")
def photo(tmp_path_factory) -> Path:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 60, size=(300, 400, 3)).astype(np.uint8)
    img[50:250, 60:260] = (90, 160, 200)  # BGR, as OpenCV writes
    img[50:250, 260:340] = (70, 120, 150)
    path = tmp_path_factory.mktemp("photo") / "box.png"
    cv2.imwrite(str(path), img)
    return path


def test_scan_writes_csv_ply_and_report(photo, tmp_path):
    out = tmp_path / "out"
    run = prism("scan", str(photo), "--points", POINTS, "--mm-per-px", "0.5", "--out", str(out))
    assert run.returncode == 0, run.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["dimensions"]["unit"] == "mm"
    assert report["dimensions"]["width"] == pytest.approx(100.0, rel=0.01)
    assert set(report["timings_ms"]) >= {"load", "refine", "scan", "assemble", "write_csv"}
    csv = np.loadtxt(out / "cloud.csv", delimiter=",")
    ply = PlyData.read(str(out / "cloud.ply"))["vertex"]
    assert csv.shape == (report["points"], 3) and ply.count == report["points"]
    np.testing.assert_allclose(csv, np.column_stack([ply["x"], ply["y"], ply["z"]]), atol=6e-4)
    assert str(out / "cloud.csv") in run.stdout


def test_spec_file_runs_the_same_job(photo, tmp_path):
    spec = {"image": photo.name, "points": [[int(v) for v in p.split(",")] for p in POINTS.split()],
            "scale": {"kind": "mm_per_px", "front": 0.5}, "formats": ["ply"]}
    spec_path = photo.parent / "job.json"
    spec_path.write_text(json.dumps(spec))
    run = prism("scan", "--spec", str(spec_path), "--out", str(tmp_path / "o"))
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "o" / "cloud.ply").exists() and not (tmp_path / "o" / "cloud.csv").exists()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["scan", "{missing}", "--points", POINTS], "missing.png"),
        (["scan", "{photo}", "--points", "1,2 3,4"], "expected 5 or 7 points"),
        (["scan", "{photo}", "--points", "61,51 258,49 261,249 262,50 939,52"], "outside"),
        (["scan", "{photo}", "--points", POINTS, "--tolerance", "500"], "tolerance"),
        (["scan", "{photo}", "--points", POINTS, "--method", "magic"], "method"),
        (["scan", "{photo}", "--points", POINTS, "--max-pixels", "100"], "limit"),
        (["scan", "{photo}", "--points", POINTS, "--distance-mm", "300"], "focal"),
        (["scan", "{photo}", "--points", POINTS, "--mm-per-px", "abc"], "mm-per-px"),
        (["scan", "{photo}", "--points", POINTS, "--cloud", "volume", "--mm-per-px", "0.001"],
         None),
        (["scan", "{garbage}", "--points", POINTS], "garbage.png"),
        (["scan", "{truncated}", "--points", POINTS], "truncated.png"),
        (["scan", "--bogus-flag"], "bogus"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(photo, tmp_path, args, needle):
    (tmp_path / "garbage.png").write_bytes(b"this is not an image")
    (tmp_path / "truncated.png").write_bytes(photo.read_bytes()[:300])
    paths = {"photo": str(photo), "missing": str(tmp_path / "missing.png"),
             "garbage": str(tmp_path / "garbage.png"), "truncated": str(tmp_path / "truncated.png")}
    argv = [a.format(**paths) for a in args] + ["--out", str(tmp_path / "o")]
    run = prism(*argv)
    if needle is None:  # a legal job: just must not crash
        assert run.returncode == 0, run.stderr
        return
    assert run.returncode == 2, (run.returncode, run.stdout, run.stderr)
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert needle in lines[0], lines[0]


def test_volume_over_point_limit_is_refused(photo, tmp_path):
    spec = {"image": str(photo), "points": [[int(v) for v in p.split(",")] for p in POINTS.split()],
            "cloud": "volume", "max_points": 1000}
    (tmp_path / "job.json").write_text(json.dumps(spec))
    run = prism("scan", "--spec", str(tmp_path / "job.json"), "--out", str(tmp_path / "o"))
    assert run.returncode == 2 and "over the limit" in run.stderr


def test_schema_prints_json_schema():
    run = prism("schema")
    assert run.returncode == 0
    assert json.loads(run.stdout)["title"] == "ScanSpec"

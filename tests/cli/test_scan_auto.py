"""`prism scan IMAGE --points auto` in a subprocess: measured with no clicks, or exit 2 with the reason."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismsynth.scenes import clutter_scene, empty_scene


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=300)


def _save(image: np.ndarray, path: Path) -> Path:
    cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    return path


def test_auto_points_measure_the_box(tmp_path):
    scene = clutter_scene(2)
    photo = _save(scene.image, tmp_path / "box.png")
    out = tmp_path / "out"
    run = prism("scan", str(photo), "--points", "auto", "--out", str(out), "--format", "csv")
    assert run.returncode == 0, run.stderr + run.stdout
    report = json.loads((out / "report.json").read_text())
    assert report["points_source"] == "auto"
    auto = report["auto_points"]
    assert auto["confidence"] >= 0.6 and auto["reason"] is None
    found = np.array(list(auto["points"].values()))
    # Every found point on a true corner (the renderer's projection), within 3 px.
    gaps = np.linalg.norm(found[:, None] - scene.vertices_px[None], axis=2).min(axis=1)
    assert gaps.max() <= 3.0
    assert report["side_face"] == auto["side_face"]


def test_no_box_exits_2_with_the_reason(tmp_path):
    photo = _save(empty_scene(1), tmp_path / "empty.png")
    run = prism("scan", str(photo), "--points", "auto", "--out", str(tmp_path / "out"))
    assert run.returncode == 2
    lines = [line for line in (run.stderr + run.stdout).splitlines() if line.strip()]
    # The scene's clutter may leave one face-like region: either refusal says why, in one line.
    assert len(lines) == 1 and ("no box found" in lines[0] or "only one face visible" in lines[0]), lines
    assert not (tmp_path / "out" / "report.json").exists()


@pytest.mark.parametrize(("args", "words"), [
    (["--points", "1,1 2,2 3,3 4,4 5,5", "--hint", "3,4"], "go with --points auto"),
    (["--points", "auto", "--hint", "3"], "expected X,Y"),
    (["--points", "auto", "--hint", "3,4", "--roi", "0,0,50,50"], "not both"),
])
def test_bad_auto_flags_exit_2(tmp_path, args, words):
    photo = _save(empty_scene(1), tmp_path / "empty.png")
    run = prism("scan", str(photo), *args, "--out", str(tmp_path / "out"))
    assert run.returncode == 2
    assert words in run.stderr + run.stdout

"""`prism scan VIDEO --points ... --points-frame N` in a subprocess (issue 29): the points of one
frame tracked to the selected frames, tracked_points.json, each frame measured or one joint box."""

from __future__ import annotations

import functools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from prismsynth import Box
from prismsynth.video import moving_clip, write_video

BOX = Box(120.0, 80.0, 60.0)


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=600)


@functools.cache
def _clip() -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    images, points = moving_clip(BOX, 21, image_size=(640, 360), focal_px=600.0, sway_deg=8.0, seed=0)
    return tuple(images), tuple(points)


@pytest.fixture
def video(tmp_path: Path) -> Path:
    path = tmp_path / "clip.avi"
    write_video(_clip()[0], path, codec="MJPG")
    return path


def _points(index: int) -> str:
    return " ".join(f"{x:.2f},{y:.2f}" for x, y in _clip()[1][index])


def test_points_of_one_frame_measure_every_selected_frame(video: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    run = prism("scan", str(video), "--points", _points(10), "--points-frame", "10", "--frames", "0,10,20",
                "--width-mm", "120", "--out", str(out), "--format", "csv")
    assert run.returncode == 0, run.stderr + run.stdout
    tracked = json.loads((out / "tracked_points.json").read_text())
    assert sorted(tracked, key=int) == ["0", "10", "20"]
    for key, entry in tracked.items():
        pts = np.array(entry["points"])
        assert pts.shape == (7, 2)
        # MJPG decoded frames against the renderer's corners: within 2 px.
        assert np.linalg.norm(pts - _clip()[1][int(key)], axis=1).max() < 2.0, key
        assert {"inliers", "fb_error_px", "confidence"} <= entry["quality"].keys()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"]["measured"] == 3
    assert summary["tracking"]["points_frame"] == 10 and summary["tracking"]["left_out"] == {}
    for name, true in (("height", 80.0), ("depth", 60.0)):
        assert abs(summary["dimensions"][name]["median"] / true - 1) < 0.03


def test_points_frame_flags_are_checked(video: Path, tmp_path: Path) -> None:
    run = prism("scan", str(video), "--points", _points(0)[: _points(0).rfind(" ", 0, -20)], "--points-frame",
                "0", "--out", str(tmp_path / "o"))
    assert run.returncode == 2 and "seven points" in run.stdout + run.stderr
    run = prism("scan", str(video), "--points", _points(0), "--points-frame", "99",
                "--out", str(tmp_path / "p"))
    assert run.returncode == 2 and "past the video's end" in run.stdout + run.stderr
    run = prism("scan", str(video), "--points", _points(0), "--points-frame", "0", "--fit", "joint",
                "--out", str(tmp_path / "q"))
    assert run.returncode == 2 and "known edge" in run.stdout + run.stderr

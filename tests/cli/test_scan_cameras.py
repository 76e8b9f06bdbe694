"""`prism scan` with what real cameras give: a calibrated camera.json (lens distortion removed),
the photo's own EXIF focal length, none at all (fitted), and a video whose frames share one
pooled focal length. Each run in a subprocess, checked against the rendered box's truth."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore.camera import CameraModel
from prismsynth import Box, CameraExif, Realism, Style, render_clip, render_oblique_view, write_video

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True, text=True,
                          timeout=300)


def points(scene) -> str:
    return " ".join(f"{x:.1f},{y:.1f}" for x, y in (scene.points[n] for n in NAMES))


def close(report: dict, rel: float) -> None:
    dims = report["dimensions"]
    for name, truth in (("width", 120.0), ("height", 80.0), ("depth", 60.0)):
        assert abs(dims[name] / truth - 1) < rel, (name, dims)


@pytest.fixture(scope="module")
def distorted(tmp_path_factory):
    """A JPEG through a lens with barrel distortion (k1 -0.12), EXIF carrying its focal length,
    and camera.json describing that camera exactly."""
    realism = Realism(k1=-0.12, exif=CameraExif())
    scene = render_oblique_view(BOX, style=Style(jpeg_quality=92), realism=realism, seed=3)
    folder = tmp_path_factory.mktemp("camera")
    (folder / "box.jpg").write_bytes(scene.jpeg)
    h, w = scene.image.shape[:2]
    model = CameraModel(fx=scene.focal_px, fy=scene.focal_px, cx=(w - 1) / 2, cy=(h - 1) / 2,
                        dist=list(realism.distortion()), image_width=w, image_height=h)
    (folder / "camera.json").write_text(model.model_dump_json())
    return scene, folder


def test_camera_json_removes_the_distortion_and_gives_the_focal(distorted, tmp_path):
    scene, folder = distorted
    run = prism("scan", str(folder / "box.jpg"), "--points", points(scene), "--width-mm", "120",
                "--camera", str(folder / "camera.json"), "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["camera"]["focal_source"] == "camera" and report["camera"]["undistorted"] is True
    close(report, 0.01)
    # The summary line carries each dimension's uncertainty and where the focal length came from.
    assert re.search(r"120\.00 \(given\) x \d+\.\d\d ± \d+\.\d\d x \d+\.\d\d ± \d+\.\d\d mm  focal "
                     r"\d+ px \(camera\)", run.stdout), run.stdout


def test_the_photos_exif_gives_the_focal_when_none_is_given(distorted, tmp_path):
    scene, folder = distorted
    run = prism("scan", str(folder / "box.jpg"), "--points", points(scene), "--width-mm", "120",
                "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    camera = json.loads((tmp_path / "report.json").read_text())["camera"]
    assert camera["focal_source"] == "exif"
    # EXIF stores whole 35 mm millimetres: the focal length read back is within that rounding.
    assert camera["focal_px"] == pytest.approx(scene.focal_px, rel=0.03)


def test_a_bad_camera_file_is_one_line(tmp_path, distorted):
    scene, folder = distorted
    (tmp_path / "camera.json").write_text('{"fx": -1}')
    run = prism("scan", str(folder / "box.jpg"), "--points", points(scene), "--camera",
                str(tmp_path / "camera.json"), "--out", str(tmp_path / "out"))
    assert run.returncode == 2 and run.stderr.count("\n") == 1
    assert "is not a camera model" in run.stderr


def test_a_videos_frames_share_one_pooled_focal_length(tmp_path):
    scenes = render_clip(BOX, 5, seed=5, focal_px=900.0, yaw_deg=35.0, pitch_deg=20.0)
    write_video((s.image for s in scenes), tmp_path / "clip.avi", codec="MJPG")
    clicks = " ".join(f"{x:.0f},{y:.0f}" for x, y in (scenes[0].points[n] for n in NAMES))
    run = prism("scan", str(tmp_path / "clip.avi"), "--points", clicks, "--width-mm", "120",
                "--out", str(tmp_path / "out"))
    assert run.returncode == 0, run.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(summary["focal"]["frames"]) == [0, 1, 2, 3, 4]
    assert summary["focal"]["pooled_px"] == pytest.approx(900.0, rel=0.03)
    for frame in range(5):
        report = json.loads((tmp_path / "out" / f"frame_{frame:06d}" / "report.json").read_text())
        assert report["camera"]["focal_source"] == "pooled"
        assert report["camera"]["focal_px"] == pytest.approx(summary["focal"]["pooled_px"], abs=1e-3)
        close(report, 0.02)
    assert "focal length pooled over 5 frames" in run.stdout
    assert np.isfinite(summary["dimensions"]["depth"]["median"])


def test_a_photo_without_any_focal_length_has_it_fitted(tmp_path):
    scene = render_oblique_view(BOX, seed=2)
    path = tmp_path / "box.png"
    cv2.imwrite(str(path), cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR))
    run = prism("scan", str(path), "--points", points(scene), "--width-mm", "120",
                "--out", str(tmp_path / "o"))
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["camera"]["focal_source"] == "fitted"
    assert report["camera"]["focal_px"] == pytest.approx(scene.focal_px, rel=0.02)
    close(report, 0.01)
    assert Path(tmp_path / "o" / "overlay.jpg").stat().st_size > 0

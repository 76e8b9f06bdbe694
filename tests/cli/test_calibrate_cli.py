"""`prism calibrate` end to end in a subprocess: OpenCV's real calibration photos (Debian's
opencv-doc, which scripts/setup installs) give a camera.json; bad input is one line and exit 2."""

from __future__ import annotations

import gzip
import re
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore.camera import CameraModel

OPENCV_DATA = Path("/usr/share/doc/opencv-doc/examples/data")
LEFT = [f"left{i:02d}.jpg" for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14)]  # no left10


def prism(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> list[Path]:
    """The 13 photos: opencv-doc's own files, or decompressed copies when it ships them gzipped."""
    if all((OPENCV_DATA / n).is_file() for n in LEFT):
        return [OPENCV_DATA / n for n in LEFT]
    if all((OPENCV_DATA / f"{n}.gz").is_file() for n in LEFT):
        folder = tmp_path_factory.mktemp("opencv-data")
        for n in LEFT:
            with gzip.open(OPENCV_DATA / f"{n}.gz") as fin, (folder / n).open("wb") as fout:
                shutil.copyfileobj(fin, fout)
        return [folder / n for n in LEFT]
    pytest.fail(f"OpenCV's calibration photos ({OPENCV_DATA}/left01.jpg ...) are missing: install "
                "Debian's opencv-doc package (scripts/setup does)")


def test_real_photos_give_a_camera_model(photos, tmp_path):
    out = tmp_path / "cam" / "camera.json"
    run = prism("calibrate", *map(str, photos), "--board", "9x6", "--square-mm", "25", "--out", str(out),
                "--name", "OpenCV left camera")
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""
    camera = CameraModel.model_validate_json(out.read_text())
    assert (camera.image_width, camera.image_height) == (640, 480) and camera.name == "OpenCV left camera"
    assert 530 < camera.fx < 540 and 530 < camera.fy < 540 and len(camera.dist) == 5
    assert camera.rms_px is not None and camera.rms_px < 0.5
    rms = float(re.search(r"RMS reprojection error ([\d.]+) px", run.stdout)[1])
    assert rms == pytest.approx(camera.rms_px, abs=5e-4)
    fx = float(re.search(r"fx ([\d.]+) \+- ([\d.]+) px", run.stdout)[1])
    assert fx == pytest.approx(camera.fx, abs=0.005)
    assert f"k1 {camera.dist[0]:+.5f}" in run.stdout
    assert "views used     13 of 13: left01.jpg, left02.jpg" in run.stdout
    assert str(out) in run.stdout


def _no_board_photo(path: Path, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    cv2.imwrite(str(path), cv2.GaussianBlur(rng.integers(0, 256, (480, 640, 3), dtype=np.uint8), (0, 0), 3))
    return path


def test_folder_with_too_few_boards_is_one_line_and_exit_2(photos, tmp_path):
    folder = tmp_path / "shots"
    folder.mkdir()
    for src in photos[:2]:
        shutil.copy(src, folder / src.name)
    _no_board_photo(folder / "wall.png", 1)
    _no_board_photo(folder / "floor.png", 2)
    (folder / "notes.txt").write_text("not a photo, not looked at")
    out = tmp_path / "camera.json"
    run = prism("calibrate", str(folder), "--board", "9x6", "--square-mm", "25", "--out", str(out))
    assert run.returncode == 2
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("prism: error: "), run.stderr
    assert "found in 2 of 4 photos" in lines[0] and "at least 3" in lines[0]
    assert f"{folder / 'floor.png'}, {folder / 'wall.png'}" in lines[0] and "left01" not in lines[0]
    assert "Traceback" not in run.stderr and not out.exists()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["{p0}", "{p1}", "{p2}", "--board", "9by6", "--square-mm", "25"], "--board '9by6'"),
        (["{p0}", "{p1}", "{p2}", "--board", "2x6", "--square-mm", "25"], "--board '2x6'"),
        (["{p0}", "{p1}", "{p2}", "--board", "9x6", "--square-mm", "-25"], "--square-mm '-25'"),
        (["{p0}", "{p1}", "{p2}", "--board", "9x6", "--square-mm", "abc"], "--square-mm 'abc'"),
        (["{p0}", "{small}", "--board", "9x6", "--square-mm", "25"], "small.png is 320x240 px"),
        (["{p0}", "{missing}", "--board", "9x6", "--square-mm", "25"], "missing.jpg"),
        (["{p0}", "{garbage}", "--board", "9x6", "--square-mm", "25"], "garbage.jpg"),
        (["{empty_dir}", "--board", "9x6", "--square-mm", "25"], "holds no photos"),
        (["{p0}", "{p1}", "{p2}", "--board", "9x6", "--square-mm", "25", "--max-pixels", "1000"], "limit"),
        (["{p0}", "{p1}", "{p2}", "--square-mm", "25"], "--board"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(photos, tmp_path, args, needle):
    (tmp_path / "garbage.jpg").write_bytes(b"not a photo")
    (tmp_path / "empty").mkdir()
    cv2.imwrite(str(tmp_path / "small.png"), cv2.imread(str(photos[0]))[::2, ::2])
    values = {"p0": photos[0], "p1": photos[1], "p2": photos[2], "small": tmp_path / "small.png",
              "missing": tmp_path / "missing.jpg", "garbage": tmp_path / "garbage.jpg",
              "empty_dir": tmp_path / "empty"}
    run = prism("calibrate", *[a.format(**{k: str(v) for k, v in values.items()}) for a in args],
                "--out", str(tmp_path / "camera.json"))
    assert run.returncode == 2
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("prism: error: "), run.stderr
    assert needle in lines[0]
    assert not (tmp_path / "camera.json").exists()

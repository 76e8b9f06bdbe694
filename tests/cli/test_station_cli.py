"""prism board, prism station calibrate and prism scan --station, as a user runs them (subprocesses
of the installed command), on rendered station photos and on OpenCV's real chessboard photos."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore.geometry.calibration import calibrate_images
from prismcore.io.images import load_image
from prismsynth.station import calibration_views, station_scene

PRISM = Path(sys.executable).with_name("prism")
OPENCV_DATA = Path("/usr/share/doc/opencv-doc/examples/data")
LEFT = [f"left{i:02d}.jpg" for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14)]


def prism(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(PRISM), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=300)


def _save(path: Path, rgb: np.ndarray) -> Path:
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def test_prism_board_writes_the_png_the_pdf_and_the_json(tmp_path) -> None:
    run = prism("board", "--out", "b", "--paper", "A3", "--squares", "9x6", "--px-per-mm", "4", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    spec = json.loads((tmp_path / "b/board.json").read_text())
    for key in ("dictionary", "squares_x", "squares_y", "square_mm", "marker_mm", "size_mm", "png_px_per_mm"):
        assert key in spec
    png = cv2.imread(str(tmp_path / "b/board.png"), cv2.IMREAD_GRAYSCALE)
    assert png.shape == (round(spec["size_mm"][1] * 4), round(spec["size_mm"][0] * 4))
    assert (tmp_path / "b/board.pdf").read_bytes().startswith(b"%PDF")


@pytest.fixture(scope="module")
def station_dir(tmp_path_factory) -> tuple[Path, object]:
    d = tmp_path_factory.mktemp("station")
    sc = station_scene(4)
    _save(d / "plate.png", sc.plate)
    _save(d / "photo.jpg", sc.photo)
    for i, view in enumerate(calibration_views(sc.setup, 8, 1)):
        _save(d / f"calib{i}.jpg", view)
    (d / "board.json").write_text(json.dumps(sc.setup.board.describe()))
    return d, sc


def test_a_station_calibrated_from_board_photos_measures_a_part_with_no_click(station_dir) -> None:
    d, sc = station_dir
    calib = sorted(p.name for p in d.glob("calib*.jpg"))
    run = prism("station", "calibrate", "--board", "board.json", "--plane", "plate.png",
                "--plate", "plate.png", *calib, "--out", "station.json", cwd=d)
    assert run.returncode == 0, run.stderr
    assert "RMS" in run.stdout
    station = json.loads((d / "station.json").read_text())
    assert abs(station["camera"]["fx"] / sc.setup.K[0, 0] - 1) < 0.01
    run = prism("scan", "photo.jpg", "--station", "station.json", "--out", "out", cwd=d)
    assert run.returncode == 0, run.stderr
    report = json.loads((d / "out/report.json").read_text())
    assert report["scale_source"] == "station"
    for key, true in sc.box.dimensions.items():
        assert abs(report["dimensions"][key] - true) <= max(0.01 * true, 1.0), (
            key, report["dimensions"], true)
        assert report["uncertainty"][key] > 0
    assert len(report["station"]["points"]) == 7 and (d / "out/cloud.ply").is_file()
    assert (d / "out/overlay.jpg").read_bytes()[:3] == b"\xff\xd8\xff"
    # --overlay-format reaches a station scan too: the same measurement, the overlay as PNG.
    run = prism("scan", "photo.jpg", "--station", "station.json", "--overlay-format", "png", "--out", "png",
                cwd=d)
    assert run.returncode == 0, run.stderr
    assert (d / "png/overlay.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (d / "png/overlay.jpg").exists()
    assert json.loads((d / "png/report.json").read_text())["dimensions"] == report["dimensions"]


@pytest.mark.parametrize(("args", "says"), [
    (("station", "calibrate", "--board", "board.json", "--plane", "plate.png", "calib0.jpg",
      "--out", "s.json"), "calibration photos"),
    (("station", "calibrate", "--board", "nope.json", "--plane", "plate.png", "--out", "s.json"),
     "nope.json"),
    (("scan", "photo.jpg", "--station", "station.json", "--points", "1,2 3,4 5,6 7,8 9,10", "--out", "o"),
     "finds the points itself"),
])
def test_bad_station_input_exits_2_with_one_line(station_dir, args, says) -> None:
    d, _ = station_dir
    run = prism(*args, cwd=d)
    assert run.returncode == 2, run.stdout + run.stderr
    assert says in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr


def test_station_calibrate_on_opencvs_real_chessboard_photos_agrees_with_prism_calibrate(
    tmp_path,
) -> None:
    if not all((OPENCV_DATA / n).is_file() for n in LEFT):
        pytest.fail(f"OpenCV's photos ({OPENCV_DATA}/left01.jpg ...) are missing: "
                    "scripts/setup installs opencv-doc")
    (tmp_path / "board.json").write_text(json.dumps({"type": "chessboard", "inner_corners": [9, 6],
                                                     "square_mm": 25}))
    photos = [OPENCV_DATA / n for n in LEFT]
    run = prism("station", "calibrate", "--board", "board.json", "--plane", photos[0], *photos[1:],
                "--out", "station.json", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    station = json.loads((tmp_path / "station.json").read_text())
    reference = calibrate_images(((str(p), load_image(p)) for p in photos), (9, 6), 25.0).camera
    cam = station["camera"]
    assert abs(cam["fx"] / reference.fx - 1) < 0.005 and abs(cam["fy"] / reference.fy - 1) < 0.005
    assert abs(cam["cx"] - reference.cx) < 2 and abs(cam["cy"] - reference.cy) < 2
    assert station["calibration"]["rms_px"] < 0.5 and station["plane"]["rms_px"] < 0.5


def test_prism_scan_board_measures_a_hand_held_photo_of_a_part_on_the_board(tmp_path) -> None:
    from prismsynth.station import station_setup

    sc = station_scene(5002, station_setup(5002), nudge=False, inside_board=True, max_size_mm=80)
    _save(tmp_path / "photo.png", sc.photo)
    (tmp_path / "board.json").write_text(json.dumps(sc.setup.board.describe()))
    run = prism("scan", "photo.png", "--board", "board.json", "--out", "out", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "out/report.json").read_text())
    assert report["scale_source"] == "board"
    assert sc.box is not None
    for key, true in sc.box.dimensions.items():
        assert abs(report["dimensions"][key] - true) <= max(0.015 * true, 1.0), (key, report["dimensions"])
    run = prism("scan", "photo.png", "--board", "board.json", "--station", "s.json", "--out", "o",
                cwd=tmp_path)
    assert run.returncode == 2 and "not both" in run.stderr

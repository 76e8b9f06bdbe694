"""`prism scan` batches, as a user runs them (subprocesses of the installed command): photos on a
station with a bad one among them, and a points table of two different parts, each with its own
points and known edge. One folder per photo, a line per photo, the results table with the
service's columns (`prism_common.results_rows.COLUMNS`), exit 1 when a photo failed."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from prism_common.results_rows import COLUMNS

from prismcore.camera import CameraModel
from prismcore.station import calibrate_station
from prismsynth.station import station_scene, station_setup

PRISM = Path(sys.executable).with_name("prism")
SAMPLES = Path(__file__).resolve().parents[2] / "samples"
BOX_POINTS = "395,293 943,331 919,761 943,331 1035,298 411,647 1009,660"  # samples/box.jpg, 120 x 80 x 60


def prism(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(PRISM), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=300)


def _save(path: Path, rgb: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def _table(folder: Path) -> tuple[list[dict[str, str]], dict]:
    with (folder / "results.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    return rows, json.loads((folder / "results.json").read_text())


@pytest.fixture(scope="module")
def station_batch(tmp_path_factory) -> tuple[Path, dict[str, dict[str, float]]]:
    """A station (its camera known, calibrated on its empty support) and two parts' photos on it."""
    d = tmp_path_factory.mktemp("batch")
    setup = station_setup(11)
    plate = station_scene(11, setup, parts=0).plate
    su = setup
    camera = CameraModel(fx=su.K[0, 0], fy=su.K[1, 1], cx=su.K[0, 2], cy=su.K[1, 2],
                         dist=[float(v) for v in su.dist], image_width=su.image_size[0],
                         image_height=su.image_size[1])
    station = calibrate_station(setup.board, plate, camera=camera, plate=plate)
    (d / "station.json").write_text(station.model_dump_json())
    truth = {}
    for name, seed in (("a", 21), ("b", 22)):
        scene = station_scene(seed, setup, max_size_mm=150)
        assert scene.box is not None
        _save(d / f"parts/{name}.jpg", scene.photo)
        truth[name] = scene.box.dimensions
    (d / "parts/broken.jpg").write_bytes(b"not a photo")
    (d / "wrong.csv").write_text("photo,clicks\na.jpg,1\n")
    return d, truth


def test_a_station_batch_measures_every_photo_but_the_bad_one_which_it_names(station_batch) -> None:
    d, truth = station_batch
    run = prism("scan", "parts/a.jpg", "parts/broken.jpg", "parts/b.jpg", "--station", "station.json",
                "--out", "out", cwd=d)
    assert run.returncode == 1, run.stdout + run.stderr  # a photo failed: the batch says so
    lines = run.stdout.splitlines()
    assert lines[0].startswith("[1/3] parts/a.jpg") and "-> out/a" in lines[0], run.stdout
    assert lines[1].startswith("[2/3] parts/broken.jpg  failed: ") and len(lines) == 4, run.stdout
    assert "2 of 3 photos measured" in lines[3] and "1 failed: parts/broken.jpg" in lines[3]
    rows, doc = _table(d / "out")
    assert tuple(rows[0]) == COLUMNS == tuple(doc["columns"])
    assert [(r["file_name"], r["state"]) for r in rows] == [
        ("a.jpg", "succeeded"), ("broken.jpg", "failed"), ("b.jpg", "succeeded")]
    assert doc["state"] == "completed_with_failures"
    broken = rows[1]
    assert broken["error"] and broken["error"] in lines[1] and broken["points_source"] == "station"
    assert broken["width"] == "" and broken["input"] == "parts/broken.jpg"
    for row in (rows[0], rows[2]):
        name = row["file_name"][0]
        assert row["points_source"] == "station" and row["unit"] == "mm" and row["station_verification"]
        for dim, true in truth[name].items():
            assert abs(float(row[dim]) - true) <= max(0.015 * true, 1.0), (name, dim, row[dim], true)
            assert float(row[f"{dim}_sigma"]) > 0
        report = json.loads((d / "out" / name / "report.json").read_text())
        assert row["warnings"] == " | ".join(report["warnings"])  # the station is not verified: warned
        assert report["warnings"] and (d / "out" / name / "cloud.ply").is_file()
    # The JSON is the same table, typed.
    for as_csv, as_json in zip(rows, doc["rows"], strict=True):
        assert as_csv == {k: "" if v is None else str(v) for k, v in as_json.items()}


@pytest.mark.parametrize(("args", "says"), [
    (("parts/a.jpg", "parts/nope.jpg", "--station", "station.json"), "no photo 'parts/nope.jpg'"),
    (("parts/a.jpg", "parts/b.jpg", "--station", "missing.json"), "missing.json"),
    (("parts/a.jpg", "parts/b.jpg", "--station", "station.json", "--points-file", "p.json"), "--points-file"),
    (("--points-table", "wrong.csv"), "columns file, points"),
    (("parts/a.jpg", "--points-table", "wrong.csv", "--station", "station.json"), "not with --station"),
])
def test_a_bad_batch_exits_2_with_one_line_and_measures_nothing(station_batch, args, says) -> None:
    d, _ = station_batch
    run = prism("scan", *args, "--out", "bad", cwd=d)
    assert run.returncode == 2, run.stdout + run.stderr
    assert says in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert not (d / "bad").exists()


def test_a_points_table_measures_two_different_parts_each_with_its_own_points(tmp_path) -> None:
    """samples/box.jpg (120 x 80 x 60 mm, its known width) and the same photo halved (its points
    halved, its known height): two parts, each measured alone, not one joint fit."""
    box = cv2.imread(str(SAMPLES / "box.jpg"))
    (tmp_path / "photos").mkdir()
    cv2.imwrite(str(tmp_path / "photos/box.png"), box)
    cv2.imwrite(str(tmp_path / "photos/small.png"), cv2.resize(box, None, fx=0.5, fy=0.5,
                                                               interpolation=cv2.INTER_AREA))
    half = " ".join(",".join(str(int(v) / 2) for v in p.split(",")) for p in BOX_POINTS.split())
    (tmp_path / "photos/points.csv").write_text(
        "file,points,width_mm,height_mm,focal_px,reference\n"
        f'box.png,"{BOX_POINTS}",120,,1400,part-A\n'
        f'small.png,"{half}",,80,700,part-B\n')
    run = prism("scan", "--points-table", "photos/points.csv", "--out", "out", cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert len(run.stdout.splitlines()) == 3 and "2 of 2 photos measured" in run.stdout, run.stdout
    rows, doc = _table(tmp_path / "out")
    assert [(r["file_name"], r["item_reference"], r["state"], r["points_source"]) for r in rows] == [
        ("box.png", "part-A", "succeeded", "clicked"), ("small.png", "part-B", "succeeded", "clicked")]
    assert doc["state"] == "succeeded" and doc["rows"][0]["p1_x"] == 395
    box_row, small_row = doc["rows"]
    assert box_row["width"] == 120 and abs(box_row["height"] - 80) < 1 and abs(box_row["depth"] - 60) < 1
    assert small_row["height"] == 80 and abs(small_row["width"] - 120) < 1.5
    assert box_row["width_sigma"] == 0 and small_row["width_sigma"] > 0  # a known edge is given, not measured
    for name in ("box", "small"):
        assert (tmp_path / "out" / name / "report.json").is_file()
        assert (tmp_path / "out" / name / "cloud.ply").is_file()
    # A photo named on the command line is found in the table by its name; one the table lacks is bad input.
    run = prism("scan", "photos/small.png", "--points-table", "photos/points.csv", "--out", "one",
                cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert [r["file_name"] for r in _table(tmp_path / "one")[0]] == ["small.png"]
    (tmp_path / "photos/other.png").write_bytes(b"")
    run = prism("scan", "photos/other.png", "--points-table", "photos/points.csv", "--out", "two",
                cwd=tmp_path)
    assert run.returncode == 2 and "no row in --points-table" in run.stderr, run.stderr

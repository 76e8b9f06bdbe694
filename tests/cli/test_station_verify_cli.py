"""`prism sample --station` then `prism station calibrate` and `prism station verify` on its
files, as a user runs them (subprocesses of the installed command): the example station's parts
measured as their true sizes say, its reference part verified, a wrong reference not, too few or
unspread placements refused."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from prismcore.io.images import load_image
from prismcore.station import Station, measure_on_station

PRISM = Path(sys.executable).with_name("prism")
REFERENCE = "70,45,30"  # prism_cli.sample_command.REFERENCE_MM


def prism(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(PRISM), *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env={"COLUMNS": "200", "PATH": "/usr/bin:/bin"},
    )


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> Path:
    """The example station rendered and calibrated as the README does (station.json beside it)."""
    d = tmp_path_factory.mktemp("verify")
    run = prism("sample", "--station", "s", cwd=d)
    assert run.returncode == 0, run.stderr
    names = {p.relative_to(d / "s").as_posix() for p in (d / "s").rglob("*") if p.is_file()}
    assert {"board.json", "plane.jpg", "empty.jpg", "true_sizes.csv", "handheld.jpg"} <= names
    assert sum(n.startswith("calib/") for n in names) == 8
    assert sum(n.startswith("parts/") for n in names) == 6
    assert sum(n.startswith("reference/") for n in names) == 7
    calib = sorted(str(p.relative_to(d)) for p in (d / "s" / "calib").glob("*.jpg"))
    run = prism(
        "station",
        "calibrate",
        "--board",
        "s/board.json",
        "--plane",
        "s/plane.jpg",
        *calib,
        "--plate",
        "s/empty.jpg",
        "--out",
        "station.json",
        cwd=d,
    )
    assert run.returncode == 0, run.stderr
    # the station's capability, stated when it is calibrated (and by prism station show)
    assert re.search(
        r"^scale: 0\.\d{3} mm/px at the support's near edge, 0\.\d{3} mm/px at its far edge$",
        run.stdout,
        re.M,
    ), run.stdout
    assert re.search(r"^capability: parts from \d+ mm, tolerances from \+-\d\.\d\d mm", run.stdout, re.M)
    shown = prism("station", "show", "station.json", cwd=d)
    assert shown.returncode == 0 and "verification: not verified" in shown.stdout, shown.stdout + shown.stderr
    assert [line for line in run.stdout.splitlines() if line.startswith(("scale:", "capability:"))] == [
        line for line in shown.stdout.splitlines() if line.startswith(("scale:", "capability:"))
    ]
    return d


def _truth(d: Path) -> dict[str, dict[str, str]]:
    with (d / "s" / "true_sizes.csv").open() as source:
        return {row["photo"]: row for row in csv.DictReader(source)}


def _references(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in (d / "s" / "reference").glob("*.jpg"))


def test_the_samples_parts_measure_as_their_true_sizes_say(sample: Path):
    station = Station.model_validate_json((sample / "station.json").read_text())
    truth = _truth(sample)
    for name in (f"parts/{k}.jpg" for k in range(1, 7)):
        measured = measure_on_station(load_image(sample / "s" / name), station)
        for key in ("width", "depth", "height"):
            true = float(truth[name][f"{key}_mm"])
            assert abs(measured.dimensions[key] - true) <= max(0.02 * true, 1.5), (
                name,
                key,
                measured.dimensions,
            )
    for name in _references(sample):  # the reference's rows hold its size, placed across the board
        row = truth[name.removeprefix("s/")]
        assert (float(row["width_mm"]), float(row["depth_mm"]), float(row["height_mm"])) == (70, 45, 30)
    # not verified yet (the tests below verify it): the scan's one line says so, warned, as
    # report.json does
    assert json.loads((sample / "station.json").read_text()).get("verification") is None
    run = prism("scan", "s/parts/1.jpg", "--station", "station.json", "--out", "unverified", cwd=sample)
    assert run.returncode == 0, run.stderr
    line = (
        r"^station not verified; camera moved \d+\.\d px \(\d+\.\d mm on the support\) since "
        r"calibration$"
    )
    assert re.search(line, run.stdout, re.M), run.stdout
    assert "warning: the station is not verified: its measurements are not checked" in run.stdout
    report = json.loads((sample / "unverified" / "report.json").read_text())
    assert report["station"]["verification"]["status"] == "not verified"
    assert any(w.startswith("the station is not verified") for w in report["warnings"])


def test_verify_passes_the_reference_and_stores_the_verification(sample: Path):
    run = prism(
        "station",
        "verify",
        "station.json",
        "--reference",
        REFERENCE,
        "--tolerance",
        "2",
        *_references(sample),
        cwd=sample,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "\nverified on " in run.stdout and "%GRR = 6 x repeatability / tolerance x 100" in run.stdout
    stored = json.loads((sample / "station.json").read_text())["verification"]
    assert stored["verified"] is True and stored["decided_by"] == []
    assert stored["reference_mm"] == {"width": 70.0, "depth": 45.0, "height": 30.0}
    assert stored["tolerance_mm"] == 2.0 and len(stored["photos"]) == 7 and stored["date"].endswith("Z")
    for name, dim in stored["dimensions"].items():
        errors, sigmas = dim["errors_mm"], dim["sigmas_mm"]
        assert all(abs(e) <= 3 * s for e, s in zip(errors, sigmas, strict=True)), name
        assert dim["grr_percent"] == pytest.approx(6 * dim["repeatability_mm"] / 4 * 100)
        # the renderer's truth: within the station's own stated one sigma of the mean reading, and
        # under the tolerance's tenth (0.4 mm of 2T = 4 mm) the rule accepts
        stated = (sum(s * s for s in sigmas) / len(sigmas)) ** 0.5
        assert abs(dim["bias_mm"]) <= min(stated, 0.4), (name, dim)
        low, high = dim["bias_ci95_mm"]
        assert low < dim["bias_mm"] < high and high - low < 2 * dim["repeatability_mm"], (name, dim)
    shown = prism("station", "show", "station.json", cwd=sample)
    line = r"^verification: verified on \d{4}-\d\d-\d\d: bias [+-]\d\.\d\d / "
    assert re.search(line, shown.stdout, re.M), shown.stdout
    reference = "  reference 70 x 45 x 30 mm (width x depth x height), 7 placements, tolerance +-2 mm"
    assert reference in shown.stdout, shown.stdout
    # The station with its verification still measures (prism scan reads it), and its one line
    # says so, with the camera's shift since calibration.
    run = prism("scan", "s/parts/1.jpg", "--station", "station.json", "--out", "out", cwd=sample)
    assert run.returncode == 0, run.stderr
    line = (
        r"^station verified on \d{4}-\d\d-\d\d: bias .* mm \(width / depth / height\); camera "
        r"moved \d+\.\d px \(\d+\.\d mm on the support\) since calibration$"
    )
    assert re.search(line, run.stdout, re.M), run.stdout
    assert "not verified" not in run.stdout
    report = json.loads((sample / "out" / "report.json").read_text())
    assert report["station"]["verification"]["status"] == "verified"
    assert report["station"]["drift"]["moved"] is False


def test_a_wrong_reference_is_not_verified_exit_1(sample: Path):
    run = prism(
        "station",
        "verify",
        "station.json",
        "--reference",
        "72,45,30",
        "--tolerance",
        "2",
        *_references(sample),
        cwd=sample,
    )
    assert run.returncode == 1, run.stdout + run.stderr
    assert "\nnot verified on " in run.stdout, run.stdout
    # the reference 2 mm too wide: the station's width read 2 mm short, give or take its own bias
    bias = re.search(r"\n  width: bias (-?\d+\.\d+) mm is significant", run.stdout)
    assert bias and float(bias.group(1)) == pytest.approx(-2.0, abs=0.1), run.stdout
    stored = json.loads((sample / "station.json").read_text())["verification"]
    assert stored["verified"] is False and stored["reference_mm"]["width"] == 72.0
    assert all(d.startswith("width: ") for d in stored["decided_by"]), stored["decided_by"]
    assert "width: placements 1, 2, 3, 4, 5, 6, 7 off by more than 3 x their stated sigma" in run.stdout


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (
            ["--reference", REFERENCE, "s/reference/1.jpg", "s/reference/2.jpg", "s/reference/3.jpg"],
            "3 placements: a verification needs 5 at least",
        ),
        (["--reference", REFERENCE, *["s/reference/3.jpg"] * 5], "centres lie 0 mm (RMS) from their mean"),
        (["--reference", "70x45x30", "s/reference/1.jpg"], "--reference '70x45x30': expected W,D,H"),
        (
            ["--reference", "45,70,30", *[f"s/reference/{k}.jpg" for k in range(1, 6)]],
            "width 45 is under its depth",
        ),
        (
            ["--reference", REFERENCE, "--tolerance", "0", *[f"s/reference/{k}.jpg" for k in range(1, 6)]],
            "tolerance 0: expected T > 0",
        ),
        (
            ["--reference", REFERENCE, *[f"s/reference/{k}.jpg" for k in range(1, 5)], "s/empty.jpg"],
            "s/empty.jpg: ",
        ),
    ],
)
def test_bad_input_exits_2_in_one_line(sample: Path, args: list[str], says: str):
    before = (sample / "station.json").read_text()
    run = prism("station", "verify", "station.json", *args, cwd=sample)
    assert run.returncode == 2, run.stdout + run.stderr
    assert run.stderr.startswith("prism: error: ") and run.stderr.strip().count("\n") == 0, run.stderr
    assert says in run.stderr, run.stderr
    assert (sample / "station.json").read_text() == before  # nothing stored


def test_a_placement_showing_one_side_exits_2_naming_it(sample: Path):
    """The reference part square to the camera's sight line (one side face seen): refused by name,
    the user told to turn it; nothing stored."""
    from dataclasses import replace

    import cv2
    import numpy as np

    from prism_cli.sample_command import _STATION_SEED, reference_placements
    from prismcore.station import default_board
    from prismsynth.station import station_scene, station_setup

    setup = station_setup(_STATION_SEED, board=default_board())  # the sample's, as it renders it
    centre = reference_placements(setup)[2]
    camera = -setup.R.T @ setup.t
    sight = float(np.degrees(np.arctan2(camera[1] - centre.y_mm, camera[0] - centre.x_mm)))
    photo = station_scene(103, setup, box=replace(centre, yaw_deg=(sight + 90.0) % 180)).photo
    assert cv2.imwrite(str(sample / "s" / "square.jpg"), cv2.cvtColor(photo, cv2.COLOR_RGB2BGR),
                       [cv2.IMWRITE_JPEG_QUALITY, 95])
    before = (sample / "station.json").read_text()
    args = ["--reference", REFERENCE, *[f"s/reference/{k}.jpg" for k in (1, 2, 4, 5)], "s/square.jpg"]
    run = prism("station", "verify", "station.json", *args, cwd=sample)
    assert run.returncode == 2, run.stdout + run.stderr
    assert run.stderr.startswith("prism: error: s/square.jpg: the station sees one side of the part "
                                 "only") and run.stderr.strip().count("\n") == 0, run.stderr
    assert (sample / "station.json").read_text() == before


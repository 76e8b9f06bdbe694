"""`prism sample --station` then `prism station calibrate` and `prism station verify` on its
files, as a user runs them (subprocesses of the installed command): the example station's parts
measured as their true sizes say, its reference part verified, a wrong reference not, too few or
unspread placements refused."""

from __future__ import annotations

import csv
import json
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
        # the renderer's truth: the bias's own interval is no wider than the tolerance's tenth
        low, high = dim["bias_ci95_mm"]
        assert low <= dim["bias_mm"] <= high and abs(dim["bias_mm"]) <= 0.4, (name, dim)
    # The station with its verification still measures (prism scan reads it).
    run = prism("scan", "s/parts/1.jpg", "--station", "station.json", "--out", "out", cwd=sample)
    assert run.returncode == 0, run.stderr


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
    assert "\nnot verified on " in run.stdout and "width: bias -1.8" in run.stdout, run.stdout
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

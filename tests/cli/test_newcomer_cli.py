"""Rough edges a newcomer hit with `prism scan` on the sample photo (issue 30): what the screen
and report.json say about a large point loss, the help's synopsis, a given or found figure."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pytest
from typer.main import get_command
from typer.testing import CliRunner

from prism_cli.main import cli
from prismcore.outputs import overlay_report
from prismcore.report import ScanReport

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "box.jpg"
# P1..P5 of samples/job.json: measured with the paper's colour scan, the front face's colour
# strays from its corner's (the seed) and the cloud keeps 1,057 of its 257,481 pixels.
FIVE = "395,293 943,331 919,761 943,331 1035,298"


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=120)


def test_a_large_point_loss_is_a_warning_on_screen_and_in_the_report(tmp_path):
    run = prism("scan", str(SAMPLE), "--points", FIVE, "--method", "paper", "--width-mm", "120",
                "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["point_loss"] > 0.9
    loss = [w for w in report["warnings"] if w.startswith("point loss")]
    assert len(loss) == 1, report["warnings"]
    assert "1,057 of the front face's 257,481" in loss[0], loss
    assert "tolerance (12)" in loss[0], loss
    assert f"warning: {loss[0]}" in " ".join(run.stdout.split()), run.stdout


def test_a_small_point_loss_is_no_warning(tmp_path):
    run = prism("scan", "--spec", str(SAMPLE.with_name("job.json")), "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["point_loss"] < 0.01
    assert not [w for w in report["warnings"] if "point loss" in w], report["warnings"]


@pytest.mark.parametrize(("scale", "words"), [
    ((), "no scale given: the dimensions are in pixels, not mm; give a scale to measure in mm: "),
    (("--focal-px", "1400"), "no scale: a focal length without the shooting distance gives none, so the "
                             "dimensions are in pixels, not mm; add the distance (--distance-mm"),
], ids=["no-scale", "focal-without-distance"])
def test_a_scan_in_pixels_says_so_on_screen_and_in_the_report(tmp_path, scale, words):
    # Exit 0 with figures in px: the warning says they are not mm, and how to give a scale.
    run = prism("scan", str(SAMPLE), "--points", FIVE, *scale, "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["dimensions"]["unit"] == "px"
    [warned] = [w for w in report["warnings"] if "in pixels, not mm" in w]
    assert warned.startswith(words) and "--width-mm" in warned and "--mm-per-px" in warned, warned
    assert f"warning: {warned}" in " ".join(run.stdout.split()), run.stdout


def test_a_scan_with_a_scale_has_no_pixels_warning(tmp_path):
    run = prism("scan", str(SAMPLE), "--points", FIVE, "--width-mm", "120", "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["dimensions"]["unit"] == "mm"
    assert not [w for w in report["warnings"] if "pixels" in w], report["warnings"]


def _commands(command: click.Command, path: tuple[str, ...] = ()):
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


HELPED = [(path, param.name, text) for path, command in _commands(get_command(cli))
          for param in command.params
          for text in re.findall(r"\\?\[[^\]]*\]", getattr(param, "help", None) or "")]


def test_the_scan_synopsis_shows_p6_and_p7():
    assert any(text.endswith("[x6,y6 x7,y7]") for _, _, text in HELPED), HELPED


@pytest.mark.parametrize(("path", "name", "text"), HELPED, ids=[f"{' '.join(p)} --{n}" for p, n, _ in HELPED])
def test_bracketed_help_is_shown_as_written(path, name, text):
    # The help is plain click text: "[x6,y6 x7,y7]" shows as written (under rich markup it was a
    # tag and vanished; rich's escape "\\[" would now show its backslash).
    shown = CliRunner().invoke(cli, [*path, "--help"], env={"COLUMNS": "2000"}, terminal_width=2000).output
    assert text in " ".join(shown.split()) and "\\[" not in shown, shown


def test_a_given_edge_is_given_and_found_points_are_said_to_be_found(tmp_path, monkeypatch):
    run = prism("scan", str(SAMPLE), "--points", "auto", "--width-mm", "120", "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    line = run.stdout.splitlines()[0]
    # The known edge is the length given, not a measurement "± 0.00".
    assert " 120.00 (given) x 79.99 ± " in line and "± 0.00" not in line, line
    assert line.endswith("points found (confidence 0.99)"), line
    report = ScanReport.model_validate_json((tmp_path / "report.json").read_text())
    notes = overlay_report.report_notes(report)
    assert "width 120.00 mm (given)" in notes and "points found (confidence 0.99)" in notes, notes
    # The overlay's key calls the crosses found points, not clicks.
    keys = []
    monkeypatch.setattr(overlay_report, "draw_overlay", lambda *a, **k: keys.append(k["points_key"]))
    image = np.zeros((1024, 1280, 3), np.uint8)
    overlay_report.overlay_from_report(image, report)
    overlay_report.overlay_from_report(image, report.model_copy(update={"points_source": None}))
    # On a station (or a board) nobody clicked: the points are the fitted box's.
    overlay_report.overlay_from_report(image, report.model_copy(update={"scale_source": "station"}))
    assert keys == ["found point", "click", "fitted box's point"]


def test_the_serve_banner_names_the_page():
    from rich.text import Text

    from prism_cli.serve_command import ready_line
    line = Text.from_markup(ready_line(8123)).plain
    assert line == ("ready: API http://127.0.0.1:8123 (docs at /docs); the page: http://127.0.0.1:8123/app/ "
                    "(log in with the API key below)"), line

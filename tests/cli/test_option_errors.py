"""A bad value of a scale option is told by the option's name (issue 37): exit 2 and one line,
"--width-mm must be > 0", never the spec's field path (scale.edge.length_mm) or pydantic's words."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from prism_cli.main import main

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "box.jpg"
FIVE = "395,293 943,331 919,761 943,331 1035,298"
SEVEN = [[395, 293], [943, 331], [919, 761], [943, 331], [1035, 298], [1010, 720], [430, 700]]


@pytest.mark.parametrize(("flags", "line"), [
    (["--width-mm", "-3"], "--width-mm must be > 0"),
    (["--width-mm", "0"], "--width-mm must be > 0"),
    (["--height-mm", "-0.5"], "--height-mm must be > 0"),
    (["--depth-mm", "nan"], "--depth-mm must be a finite number"),
    (["--depth-mm", "1e9"], "--depth-mm: 1e+09 mm is out of range: a length is 0.001 to 1e+06 mm"),
    (["--mm-per-px", "0"], "--mm-per-px must be > 0"),
    (["--mm-per-px", "0.2,-1"], "--mm-per-px SIDE must be > 0"),
    (["--distance-mm", "-5"], "--distance-mm must be > 0"),
    (["--distance-mm", "inf"], "--distance-mm must be a finite number"),
    (["--distance-mm", "500", "--focal-px", "0"], "--focal-px must be > 0"),
    (["--width-mm", "120", "--spacing-mm", "-1"], "--spacing-mm must be > 0"),
])
@pytest.mark.parametrize("command", ["scan", "submit"])
def test_a_bad_scale_option_is_named_in_one_line(capsys, tmp_path, command: str, flags: list[str], line: str):
    where = ["--out", str(tmp_path)] if command == "scan" else ["--key", "k", "--api", "http://127.0.0.1:9"]
    code = main([command, str(SAMPLE), "--points", FIVE, *flags, *where])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert err == f"prism: error: {line}\n"
    assert not list(tmp_path.iterdir())  # nothing measured, nothing written


@pytest.mark.parametrize(("flags", "line"), [
    (["--width-mm", "-3"], "--width-mm must be > 0"),
    (["--depth-mm", "0"], "--depth-mm must be > 0"),
])
def test_a_bad_known_edge_of_a_joint_fit_is_named_too(capsys, tmp_path, flags: list[str], line: str):
    points = tmp_path / "points.json"
    points.write_text(json.dumps([SEVEN, SEVEN]))
    code = main(["scan", str(SAMPLE), str(SAMPLE), "--points-file", str(points), *flags,
                 "--out", str(tmp_path / "out")])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert err == f"prism: error: {line}\n"

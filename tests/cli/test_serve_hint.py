"""`prism serve`'s `try:` line, built for the shell it will be pasted into: prism's full path
unless `prism` on PATH is this one, PRISM_API_URL unless the port is the client's default, the
key unless PRISM_API_KEYS holds the keys, the sample by its full path (or rendered by `prism
sample` where there is none). tests/test_docs.py runs the printed line for real."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import pytest

from prism_cli.serve_command import SAMPLE_POINTS, _prism_command, try_line

PHOTO = Path("/opt/prism/samples/box.jpg")


def test_the_default_port_needs_no_url_and_the_key_is_given():
    line = try_line(8000, "k-abc", prism="prism", photo=PHOTO)
    assert line == (f"PRISM_API_KEY=k-abc prism submit {PHOTO} --points '{SAMPLE_POINTS}' "
                    "--width-mm 120 --wait")


def test_another_port_is_named_and_keys_from_the_environment_are_not_printed():
    line = try_line(8123, None, prism="/x/.venv/bin/prism", photo=PHOTO)
    assert line.startswith("PRISM_API_URL=http://127.0.0.1:8123 /x/.venv/bin/prism submit ")
    assert "PRISM_API_KEY" not in line


def test_without_the_sample_photo_one_is_rendered_first():
    line = try_line(8000, "k-abc", prism="prism", photo=None)
    assert line == ("prism sample --out prism-sample && PRISM_API_KEY=k-abc prism submit --spec "
                    "prism-sample/job.json --wait")


def test_every_word_is_quoted_for_the_shell():
    line = try_line(8000, "k-a b", prism="'/my dir/prism'", photo=Path("/my dir/box.jpg"))
    words = shlex.split(line)
    assert words[:3] == ["PRISM_API_KEY=k-a b", "/my dir/prism", "submit"]
    assert words[3] == "/my dir/box.jpg" and words[5] == SAMPLE_POINTS


def test_seven_points_so_the_result_is_within_its_sigma():
    assert len(SAMPLE_POINTS.split()) == 7


@pytest.mark.parametrize("on_path", [True, False])
def test_prism_is_named_by_its_path_unless_path_finds_this_one(monkeypatch, on_path: bool):
    here = Path(sys.executable).parent
    monkeypatch.setenv("PATH", f"{here}:/usr/bin:/bin" if on_path else "/usr/bin:/bin")
    assert _prism_command() == ("prism" if on_path else shlex.quote(str(here / "prism")))

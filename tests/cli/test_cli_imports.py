"""`prism` imports what a command uses when it runs (issue 28): `prism --help` and every command's
--help load no engine, numpy, OpenCV, scipy, HTTP client or rich (the help is plain click text;
pydantic, yes: typer coerces a command's parameters with it), and a scan of a photo loads neither
the client nor the joint fit, the calibration or the video search. Not a timing test:
the modules in a fresh process's ``sys.modules``, which is what the time follows
(`benchmarks/speed.py` prints the time)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import click
from typer.main import get_command

from prism_cli import calibrate_command, scan_command
from prism_cli.main import cli

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "box.jpg"
SEVEN = "395,293 943,331 919,761 943,331 1035,298 411,647 1009,660"

# Each costs tens to hundreds of ms of CPU to import (scipy.optimize ~0.5 s, scipy.stats ~1 s).
HELP_FORBIDDEN = ("numpy", "cv2", "scipy", "polars", "httpx", "prism_common", "rich",
                  "prismsynth", "prismcore.spec", "prismcore.multiview.joint")
SCAN_FORBIDDEN = ("httpx", "prism_common", "scipy.stats", "prismsynth", "prismcore.multiview.joint",
                  "prismcore.geometry.calibration", "prismcore.locate.search",
                  "prismcore.video.point_search", "prismcore.station", "rich.progress")

# Runs prism's own entry (`main`) in a fresh interpreter, output swallowed, then prints the
# modules it imported.
_RUN = """
import contextlib, io, json, sys
from prism_cli.main import main
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    assert code == 0, (argv, code)
print(json.dumps(sorted(sys.modules)))
"""


def _modules_after(*argvs: list[str]) -> set[str]:
    run = subprocess.run([sys.executable, "-c", _RUN, json.dumps(argvs)], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return set(json.loads(run.stdout.splitlines()[-1]))


def _loaded(modules: set[str], names: tuple[str, ...]) -> list[str]:
    return sorted(m for m in modules if any(m == n or m.startswith(n + ".") for n in names))


def _command_paths(command: click.Command, path: tuple[str, ...] = ()) -> list[list[str]]:
    paths = [list(path)]
    for name, sub in getattr(command, "commands", {}).items():
        paths += _command_paths(sub, (*path, name))
    return paths


def test_help_imports_no_heavy_module():
    helps = [[*path, "--help"] for path in _command_paths(get_command(cli))]
    assert len(helps) > 15  # prism, its commands and station's
    modules = _modules_after(*helps)
    loaded = _loaded(modules, HELP_FORBIDDEN)
    assert not loaded, f"prism --help imports {loaded}: import them in the command that uses them"


def test_the_top_help_imports_not_even_pydantic():
    assert not _loaded(_modules_after(["--help"]), ("pydantic",))


def test_a_photo_scan_imports_only_what_it_uses(tmp_path):
    modules = _modules_after(["scan", str(SAMPLE), "--points", SEVEN, "--focal-px", "1400",
                              "--distance-mm", "279.132", "--out", str(tmp_path)])
    assert "prismcore.scan.pipeline" in modules  # it did scan
    loaded = _loaded(modules, SCAN_FORBIDDEN)
    assert not loaded, f"prism scan of a photo imports {loaded}"


def test_the_defaults_shown_without_the_engine_are_the_engines():
    from prismcore.io.images import DEFAULT_MAX_PIXELS
    from prismcore.video.frame_select import DEFAULT_MAX_FRAMES

    assert scan_command.DEFAULT_MAX_FRAMES == DEFAULT_MAX_FRAMES
    assert calibrate_command.DEFAULT_MAX_PIXELS == DEFAULT_MAX_PIXELS

"""The README's zero-click benchmark commands run as a reader would type them (a few scenes),
and print the figures the README quotes: the confusion table with its "found wrong and not
flagged" row, and the real video's frames found within 5 px of the hand marks."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # benchmark scripts, out of scripts/test --fast

ROOT = Path(__file__).resolve().parents[3]


def _run(*argv: str) -> str:
    done = subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_zero_click_prints_the_confusion_table_and_the_search_time():
    out = _run("benchmarks/zero_click.py", "--scenes", "3", "--seed", "200", "--show-failures")
    assert re.search(r"points within 3 px \(accepted\), box largest: \d+/3", out), out
    assert re.search(r"WRONG, NOT FLAGGED\s+0\b", out), out
    assert re.search(r"CPU time of the process .*: median \d+, p90 \d+, worst \d+", out), out


def test_zero_click_on_the_real_video_prints_its_frames_found():
    out = _run("benchmarks/zero_click_real_video.py")
    assert re.search(r"found within 5 px of the marks: \d+ of 12 frames", out), out

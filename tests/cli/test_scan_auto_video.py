"""`prism scan VIDEO --points auto` in a subprocess: every frame's points found with no clicks
(each search starting at the box the frame before showed), a frame without the box failed with
the search's reason, the others summarised.

The video is a rendered hand-held clip of a box of known size (`prismsynth.render_clip`) with
one frame of clutter and no box put in; each found point is checked against the nearest true
corner of its frame, and the dimensions as ratios (no scale: pixels).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from prismsynth import Box, write_video
from prismsynth.scenes import box_vertices_px, empty_scene
from prismsynth.video import render_clip

BOX = Box(120.0, 80.0, 60.0)
EMPTY_FRAME = 2


def clip_with_a_gap(path: Path) -> list[np.ndarray | None]:
    """Write the clip to `path`; each frame's true corners (8, 2) px, None for the empty frame."""
    clip = render_clip(BOX, 4, sway_deg=3)
    frames = [s.image for s in clip]
    frames[EMPTY_FRAME] = empty_scene(0, image_size=(640, 512))
    write_video(frames, path)
    return [None if i == EMPTY_FRAME else box_vertices_px(s)[1] for i, s in enumerate(clip)]


def test_a_video_is_measured_with_no_clicks(tmp_path):
    video = tmp_path / "clip.avi"
    corners = clip_with_a_gap(video)
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "prism_cli", "scan", str(video), "--points", "auto",
                          "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr + run.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"]["measured"] == 3 and summary["frames"]["failed"] == 1
    [failed] = summary["failed"]
    assert failed["frame"] == EMPTY_FRAME and failed["error"].startswith("points auto: "), failed
    for index, truth in enumerate(corners):
        if truth is None:
            assert not (out / f"frame_{index:06d}").exists()
            continue
        report = json.loads((out / f"frame_{index:06d}" / "report.json").read_text())
        assert report["points_source"] == "auto" and report["auto_points"]["reason"] is None
        for xy in report["inputs"]["points"].values():
            if xy is not None:
                assert np.linalg.norm(truth - xy, axis=1).min() <= 3.0, (index, xy)
        d = report["dimensions"]
        # The search names the faces its own way: the three edges as a set, as ratios.
        measured = sorted([d["width"], d["height"], d["depth"]])
        assert np.array(measured) / measured[-1] == pytest.approx([0.5, 80 / 120, 1.0], rel=0.01)

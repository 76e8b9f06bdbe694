"""`prism scan` writes overlay.jpg (overlay.png with --overlay-format png) beside the clouds: the
sample photo, two photos, a video's frames (in the format asked for)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore.outputs.overlay import FACE_COLORS
from prismsynth import Box, render_clip, write_video

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=300)


def _rgb(path: Path) -> np.ndarray:
    picture = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert picture is not None and picture.dtype == np.uint8 and picture.shape[2] == 3, path
    return cv2.cvtColor(picture, cv2.COLOR_BGR2RGB)


def _on_edges(picture: np.ndarray, corners: list, color: tuple[int, int, int],
              edges: tuple[int, ...] = (0, 1, 2, 3)) -> float:
    """Share of points along the quad's edges (away from the corners) drawn in `color`."""
    quad = np.asarray(corners)
    hits = total = 0
    for i in edges:
        a, b = quad[i], quad[(i + 1) % 4]
        for t in np.linspace(0.3, 0.7, 9):
            x, y = np.rint(a + t * (b - a)).astype(int)
            patch = picture[y - 1:y + 2, x - 1:x + 2].astype(int)
            hits += int(np.abs(patch - color).max(axis=2).min() <= 12)
            total += 1
    return hits / total


def test_the_sample_photo_gets_its_overlay(tmp_path):
    out = tmp_path / "out"
    run = prism("scan", "--spec", str(ROOT / "samples" / "job.json"), "--out", str(out),
                "--overlay-format", "png")
    assert run.returncode == 0, run.stderr
    assert str(out / "overlay.png") in run.stdout and not (out / "overlay.jpg").exists()
    report = json.loads((out / "report.json").read_text())
    picture = _rgb(out / "overlay.png")
    assert picture.shape == (1024, 1280, 3)
    assert report["timings_ms"]["write_overlay"] > 0
    # the faces are drawn where the report says they were fitted; the side's left edge is the
    # front's right one, drawn in the front's colour
    assert _on_edges(picture, report["faces"]["front"]["corners"], FACE_COLORS["front"]) == 1.0
    assert _on_edges(picture, report["faces"]["side"]["corners"], FACE_COLORS["side"], (0, 1, 2)) == 1.0
    photo = cv2.cvtColor(cv2.imread(str(ROOT / "samples" / "box.jpg")), cv2.COLOR_BGR2RGB)
    assert np.mean(np.all(picture == photo, axis=2)) > 0.7  # an overlay, not a new picture


def test_the_overlay_is_a_jpeg_by_default(tmp_path):
    png, jpeg = tmp_path / "png", tmp_path / "jpeg"
    for out, flags in ((png, ["--overlay-format", "png"]), (jpeg, [])):
        run = prism("scan", "--spec", str(ROOT / "samples" / "job.json"), "--out", str(out), *flags)
        assert run.returncode == 0, run.stderr
    assert str(jpeg / "overlay.jpg") in run.stdout and not (jpeg / "overlay.png").exists()
    assert (jpeg / "overlay.jpg").read_bytes()[:3] == b"\xff\xd8\xff"
    lossless, picture = _rgb(png / "overlay.png"), _rgb(jpeg / "overlay.jpg")
    # the same picture, a sixth of the bytes: JPEG's error is a grey level or two on average
    assert picture.shape == lossless.shape
    assert np.abs(picture.astype(int) - lossless).mean() < 2.0
    assert (jpeg / "overlay.jpg").stat().st_size < (png / "overlay.png").stat().st_size / 4
    report = json.loads((jpeg / "report.json").read_text())
    assert _on_edges(picture, report["faces"]["front"]["corners"], FACE_COLORS["front"]) == 1.0


def test_an_unknown_overlay_format_is_refused(tmp_path):
    run = prism("scan", "--spec", str(ROOT / "samples" / "job.json"), "--out", str(tmp_path / "o"),
                "--overlay-format", "gif")
    assert run.returncode == 2 and "--overlay-format 'gif'" in run.stderr + run.stdout


def test_two_photos_get_one_overlay_each(tmp_path):
    rng = np.random.default_rng(0)
    folder = tmp_path / "photos"
    folder.mkdir()
    for name, size in (("front.png", (300, 400)), ("side.png", (240, 320))):
        img = rng.integers(0, 60, size=(*size, 3)).astype(np.uint8)
        img[50:200, 60:260] = (90, 160, 200)
        cv2.imwrite(str(folder / name), img)
    out = tmp_path / "out"
    run = prism("scan", str(folder / "front.png"), "--side", str(folder / "side.png"),
                "--points", "61,51 258,49 259,198 62,52 258,50 61,198 258,198",
                "--mm-per-px", "0.5,0.5", "--out", str(out), "--overlay-format", "png")
    assert run.returncode == 0, run.stderr
    report = json.loads((out / "report.json").read_text())
    front, side = _rgb(out / "overlay.png"), _rgb(out / "overlay_side.png")
    assert front.shape == (300, 400, 3) and side.shape == (240, 320, 3)
    assert _on_edges(front, report["faces"]["front"]["corners"], FACE_COLORS["front"]) == 1.0
    assert _on_edges(side, report["faces"]["side"]["corners"], FACE_COLORS["side"]) == 1.0
    # each photo shows its own face only
    assert not np.all(np.abs(front.astype(int) - FACE_COLORS["side"]) <= 12, axis=2).any()
    assert not np.all(np.abs(side.astype(int) - FACE_COLORS["front"]) <= 12, axis=2).any()


@pytest.mark.parametrize(("flags", "name", "magic"), [([], "overlay.jpg", b"\xff\xd8\xff"),
                                                 (["--overlay-format", "png"], "overlay.png", b"\x89PNG")])
def test_every_measured_video_frame_gets_its_overlay(tmp_path, flags, name, magic):
    scenes = render_clip(Box(120.0, 80.0, 60.0), 4, seed=5)
    clip = tmp_path / "clip.avi"
    write_video((s.image for s in scenes), clip, codec="MJPG")
    points = " ".join(f"{x},{y}" for x, y in (np.rint(scenes[0].points[n]).astype(int) for n in NAMES))
    out = tmp_path / "out"
    run = prism("scan", str(clip), "--points", points, "--focal-px", str(scenes[0].focal_px),
                "--distance-mm", str(scenes[0].distance_mm), "--frames", "0,3", "--out", str(out), *flags)
    assert run.returncode == 0, run.stderr
    h, w = scenes[0].image.shape[:2]
    for index in (0, 3):
        folder = out / f"frame_{index:06d}"
        report = json.loads((folder / "report.json").read_text())
        assert (folder / name).read_bytes()[:len(magic)] == magic
        assert not any(p.name.startswith("overlay.") and p.name != name for p in folder.iterdir())
        picture = _rgb(folder / name)
        assert picture.shape == (h, w, 3)
        assert _on_edges(picture, report["faces"]["front"]["corners"], FACE_COLORS["front"]) == 1.0
    assert not (out / "frame_000001").exists()


def test_the_paper_method_writes_the_overlay_too(tmp_path):
    out = tmp_path / "out"
    spec = json.loads((ROOT / "samples" / "job.json").read_text())
    spec |= {"image": str(ROOT / "samples" / "box.jpg"), "method": "paper",
             "scale": {"kind": "mm_per_px", "front": 0.2}}
    spec_path = tmp_path / "job.json"
    spec_path.write_text(json.dumps(spec))
    run = prism("scan", "--spec", str(spec_path), "--out", str(out))
    assert run.returncode == 0, run.stderr
    assert _rgb(out / "overlay.jpg").shape == (1024, 1280, 3)

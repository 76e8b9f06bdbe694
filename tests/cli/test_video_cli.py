"""`prism scan VIDEO` end to end in a subprocess: a folder per frame, the summary, and bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
from plyfile import PlyData

from prismsynth import Box, render_clip, write_video

BOX = Box(120.0, 80.0, 60.0)
TRUTH = {"width": 120.0, "height": 80.0, "depth": 60.0}
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def prism(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=300)


def _clicks(scene) -> list[list[int]]:
    return [[int(v) for v in np.rint(scene.points[n])] for n in NAMES]


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A 6-frame MJPEG AVI and H.264 MP4 of BOX, and the flags that measure them."""
    scenes = render_clip(BOX, 6, seed=5)
    folder = tmp_path_factory.mktemp("video")
    write_video((s.image for s in scenes), folder / "clip.avi", codec="MJPG")
    write_video((s.image for s in scenes), folder / "clip.mp4", codec="h264")
    points = " ".join(f"{x},{y}" for x, y in _clicks(scenes[0]))
    flags = ["--points", points, "--focal-px", str(scenes[0].focal_px),
             "--distance-mm", str(scenes[0].distance_mm)]
    return folder, scenes, flags


def test_every_nth_frame_gets_a_folder_and_the_summary_agrees(clip, tmp_path):
    folder, _, flags = clip
    out = tmp_path / "out"
    run = prism("scan", str(folder / "clip.avi"), *flags, "--every", "2", "--out", str(out))
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["frame_000000", "frame_000002", "frame_000004",
                                                     "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    reports = {i: json.loads((out / f"frame_{i:06d}" / "report.json").read_text()) for i in (0, 2, 4)}
    for i, report in reports.items():
        assert report["frame"] == {"index": i, "time_s": i / 25.0}
        dims = report["dimensions"]
        assert max(abs(dims[k] - v) / v for k, v in TRUTH.items()) < 0.012, (i, dims)
        csv = np.loadtxt(out / f"frame_{i:06d}" / "cloud.csv", delimiter=",")
        assert csv.shape == (report["points"], 3)
        assert PlyData.read(str(out / f"frame_{i:06d}" / "cloud.ply"))["vertex"].count == report["points"]
    assert summary["frames"] == {"selected": 3, "measured": 3, "failed": 0}
    assert summary["selection"] == {"every": 2}
    assert summary["video"]["frame_count"] == 6 and summary["video"]["codec"] == "MJPG"
    for k in TRUTH:
        values = np.array([reports[i]["dimensions"][k] for i in (0, 2, 4)])
        assert summary["dimensions"][k]["median"] == pytest.approx(np.median(values), abs=1e-6)
        assert summary["dimensions"][k]["spread"] == pytest.approx(np.ptp(values), abs=1e-6)
    assert "spread/median" in run.stdout and "frame_000004" in run.stdout


def test_h264_mp4_sharpest_frames(clip, tmp_path):
    folder, _, flags = clip
    out = tmp_path / "out"
    run = prism("scan", str(folder / "clip.mp4"), *flags, "--sharpest", "2", "--start", "0.04",
                "--out", str(out))
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"]["measured"] == 2 and all(r["frame"] >= 1 for r in summary["per_frame"])


def test_without_frame_flags_every_frame_is_measured(clip, tmp_path):
    folder, _, flags = clip
    run = prism("scan", str(folder / "clip.avi"), *flags, "--format", "ply", "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    assert len(list(tmp_path.glob("frame_*/cloud.ply"))) == 6 and not list(tmp_path.glob("*/cloud.csv"))


def test_spec_file_with_per_frame_points_and_one_bad_frame(clip, tmp_path):
    folder, scenes, _ = clip
    frame_points = {str(i): _clicks(scenes[i]) for i in (0, 3, 5)}
    frame_points["3"][2] = [5000, 5000]  # P3 far outside the frame: this frame fails alone
    spec = {"image": "clip.avi", "frame_points": frame_points, "focal_px": scenes[0].focal_px,
            "scale": {"kind": "pinhole", "distance_mm": scenes[0].distance_mm}}
    (folder / "frames.json").write_text(json.dumps(spec))
    out = tmp_path / "out"
    run = prism("scan", "--spec", str(folder / "frames.json"), "--out", str(out))
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert [r["frame"] for r in summary["per_frame"]] == [0, 5]
    assert [f["frame"] for f in summary["failed"]] == [3] and "outside" in summary["failed"][0]["error"]
    assert sorted(p.name for p in out.glob("frame_*")) == ["frame_000000", "frame_000005"]
    assert "frame_000003 failed" in run.stdout


def test_no_frame_measured_is_exit_2(clip, tmp_path):
    folder, _, flags = clip
    bad = ["--points", "1,1 2,1 2,2 2,1 3,1", *flags[2:]]
    run = prism("scan", str(folder / "clip.avi"), *bad, "--frames", "1,2", "--out", str(tmp_path))
    assert run.returncode == 2
    assert len(run.stderr.strip().splitlines()) == 1 and "no frame of" in run.stderr
    assert json.loads((tmp_path / "summary.json").read_text())["frames"]["failed"] == 2


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["{photo}", "--every", "2"], "is not a video"),
        (["{cut}"], "truncated or corrupt MP4"),
        (["{empty}"], "no decodable frames"),
        (["{avi}", "--frames", "0,99"], "frame indices 99 out of range"),
        (["{avi}", "--frames", "0,x"], "--frames '0,x'"),
        (["{avi}", "--max-frames", "2"], "over the cap of 2"),
        (["{avi}", "--every", "0"], "frames.every"),
        (["{avi}", "--start", "9"], "past the end"),
        (["{avi}", "--start", "0.1", "--end", "0.05"], "must be after start_s"),
        (["{avi}", "--side", "{photo}"], "side_image"),
        (["{avi}", "--max-pixels", "1000"], "over the limit"),
    ],
    ids=["not-a-video", "truncated", "zero-frames", "out-of-range", "bad-indices", "over-cap",
         "every-0", "start-past-end", "end-before-start", "side-image", "max-pixels"],
)
def test_bad_video_input_is_one_line_and_exit_2(clip, tmp_path, args, needle):
    folder, _, flags = clip
    photo, cut, empty = tmp_path / "box.png", tmp_path / "cut.mp4", tmp_path / "empty.avi"
    cv2.imwrite(str(photo), np.zeros((64, 64, 3), np.uint8))
    cut.write_bytes((folder / "clip.mp4").read_bytes()[:-3000])
    cv2.VideoWriter(str(empty), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48)).release()
    paths = {"photo": str(photo), "cut": str(cut), "empty": str(empty), "avi": str(folder / "clip.avi")}
    argv = [a.format(**paths) for a in args]
    run = prism("scan", argv[0], *flags, *argv[1:], "--out", str(tmp_path / "o"))
    assert run.returncode == 2, (run.stdout, run.stderr)
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert needle in lines[0], lines[0]


@pytest.mark.parametrize(
    ("spec", "extra", "needle"),
    [
        ({"image": "clip.avi", "points": [[1, 1]] * 5}, [], "is a video: say which frames"),
        ({"image": "clip.avi", "points": [[1, 1]] * 5, "frames": {}}, ["--every", "2"], "not both"),
        ({"image": "missing.avi", "points": [[1, 1]] * 5, "frames": {}}, [], "No such file"),
    ],
    ids=["video-without-frames", "spec-and-flags", "missing"],
)
def test_bad_video_spec_files(clip, tmp_path, spec, extra, needle):
    folder, _, _ = clip
    path = folder / f"bad-{tmp_path.name}.json"
    path.write_text(json.dumps(spec))
    run = prism("scan", "--spec", str(path), *extra, "--out", str(tmp_path / "o"))
    assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert needle in run.stderr, run.stderr

"""`prism scan A.jpg B.jpg C.jpg --points-file points.json`: several photos of one part measured as one
box (issue 20, item 1), in a subprocess: the dimensions ± sigma and the views left out printed,
joint.json written; bad input is one line and exit 2."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from prismsynth import photo_like_views, save_image

pytestmark = pytest.mark.slow  # three photo-like renders and a joint fit


def prism(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prism_cli", *args], capture_output=True,
                          text=True, timeout=300, cwd=cwd)


@pytest.fixture(scope="module")
def shots(tmp_path_factory) -> tuple[Path, list, object]:
    """Three photos of one box (PNG, the renders' pixels) and their clicks; the box."""
    folder = tmp_path_factory.mktemp("joint")
    scenes = photo_like_views(2, 3)
    for k, p in enumerate(scenes):
        save_image(p.image, folder / f"view{k + 1}.png")
    return folder, scenes, scenes[0].box


def _points(scenes, wrong: int | None = None) -> list[list[list[float]]]:
    out = []
    for k, p in enumerate(scenes):
        c = {n: np.asarray(v) for n, v in p.clicks.items()}
        if k == wrong:  # the second face's far corners pulled out: a 15 % deeper box
            c["p5"] = c["p4"] + 1.15 * (c["p5"] - c["p4"])
            c["p7"] = c["p3"] + 1.15 * (c["p7"] - c["p3"])
        out.append([[float(c[f"p{i}"][0]), float(c[f"p{i}"][1])] for i in range(1, 8)])
    return out


def _known(scenes) -> list[str]:
    p = scenes[0]
    return [f"--{p.known_edge}-mm", f"{p.known_length_mm:.4f}"]


def test_three_photos_measured_as_one_box(shots, tmp_path) -> None:
    folder, scenes, box = shots
    (tmp_path / "points.json").write_text(json.dumps(_points(scenes)))
    out = tmp_path / "out"
    run = prism("scan", "view1.png", "view2.png", "view3.png", "--points-file", str(tmp_path / "points.json"),
                *_known(scenes), "--out", str(out), cwd=folder)
    assert run.returncode == 0, run.stderr
    assert "3 of 3 views as one box" in run.stdout
    assert "±" in run.stdout and "left out" not in run.stdout
    assert re.search(r"views as one box  [\d.]+ \(given\) x [\d.]+ ± ", run.stdout), run.stdout  # the edge
    result = json.loads((out / "joint.json").read_text())
    for name in ("width", "height", "depth"):
        assert result["dimensions"][name] == pytest.approx(getattr(box, f"{name}_mm"), rel=0.01)
        assert result["uncertainty"][name] >= 0
    assert [v["name"] for v in result["views"]] == ["view1.png", "view2.png", "view3.png"]
    assert all(isinstance(v["lines_left_out"], int) and v["lines_left_out"] >= 0 for v in result["views"])
    assert result["left_out"] == []


def test_a_view_with_wrong_points_is_named_and_left_out(shots, tmp_path) -> None:
    folder, scenes, box = shots
    points = _points(scenes, wrong=1)
    # Keyed by file name, in another order than the photos: the names decide.
    keyed = {"view3.png": points[2], "view1.png": points[0],
             "view2.png": {"points": points[1], "side_face": "right"}}
    (tmp_path / "points.json").write_text(json.dumps(keyed))
    out = tmp_path / "out"
    run = prism("scan", "view1.png", "view2.png", "view3.png", "--points-file", str(tmp_path / "points.json"),
                *_known(scenes), "--out", str(out), cwd=folder)
    assert run.returncode == 0, run.stderr
    assert "2 of 3 views as one box" in run.stdout
    printed = " ".join(run.stdout.split())
    assert "left out view2.png: disagrees with the other views beyond its noise" in printed
    result = json.loads((out / "joint.json").read_text())
    assert [o["name"] for o in result["left_out"]] == ["view2.png"]
    assert result["dimensions"]["depth"] == pytest.approx(box.depth_mm, rel=0.01)


@pytest.mark.parametrize(("args", "points", "message"), [
    (["a.png", "b.png", "--width-mm", "100"], None, "give --points-file"),
    (["view1.png", "view2.png", "--width-mm", "100"], [[[1, 2]] * 7], "has 1 entries for 2 photos"),
    (["view1.png", "view2.png", "--width-mm", "100"], [[[1, 2]] * 5, [[1, 2]] * 7],
     "expected seven [x, y] points"),
    (["view1.png", "view2.png", "--width-mm", "100"], {"view1.png": [[1, 2]] * 7},
     "no entry for 'view2.png'"),
    (["view1.png", "view2.png", "--mm-per-px", "0.5"], [[[1, 2]] * 7] * 2, "one known edge"),
    (["view1.png", "view2.png", "--width-mm", "-3"], [[[1, 2]] * 7] * 2, "--width-mm must be > 0"),
    (["view1.png", "view2.png", "--width-mm", "100"], "not json", "is not JSON"),
])
def test_bad_input_is_one_line_and_exit_2(shots, tmp_path, args, points, message) -> None:
    folder, _, _ = shots
    extra: list[str] = []
    if points is not None:
        path = tmp_path / "points.json"
        path.write_text(points if isinstance(points, str) else json.dumps(points))
        extra = ["--points-file", str(path)]
    run = prism("scan", *args, *extra, "--out", str(tmp_path / "out"), cwd=folder)
    assert run.returncode == 2, (run.stdout, run.stderr)
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1, run.stderr
    assert message in lines[0]


def test_a_spec_with_views_is_measured_as_one_box(shots, tmp_path) -> None:
    # The service's item shape, read by `prism scan --spec` (photos relative to the spec file).
    folder, scenes, box = shots
    points = _points(scenes)
    spec = {"views": [{"image": str(folder / f"view{k + 1}.png"), "points": p} for k, p in enumerate(points)],
            "scale": {"kind": "edge", "edge": scenes[0].known_edge, "length_mm": scenes[0].known_length_mm}}
    spec["views"][2]["name"] = "third"
    (tmp_path / "job.json").write_text(json.dumps(spec))
    out = tmp_path / "out"
    run = prism("scan", "--spec", str(tmp_path / "job.json"), "--out", str(out))
    assert run.returncode == 0, run.stderr
    assert "3 of 3 views as one box" in run.stdout
    result = json.loads((out / "joint.json").read_text())
    assert [(v["index"], v["name"]) for v in result["views"]] == [(0, "view1.png"), (1, "view2.png"),
                                                                  (2, "third")]
    for name in ("width", "height", "depth"):
        assert result["dimensions"][name] == pytest.approx(getattr(box, f"{name}_mm"), rel=0.01)
    video = {"image": "clip.avi", "fit": "joint", "frame_points": {"0": points[0], "5": points[1]},
             "scale": spec["scale"]}
    (tmp_path / "video.json").write_text(json.dumps(video))
    run = prism("scan", "--spec", str(tmp_path / "video.json"), "--out", str(out))
    assert run.returncode == 2 and "measured by the service (prism submit)" in run.stderr, run.stderr

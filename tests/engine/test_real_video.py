"""The hand-marked frames of OpenCV's cookie-box video (a real camera, focal length unknown),
measured with one known edge: the acceptance bounds of issue 15 against the box's true size."""

from __future__ import annotations

import importlib.util
import statistics
from pathlib import Path

import pytest

from prismcore import InputError, ScanSpec, run_scan

_DATA = Path(__file__).resolve().parents[2] / "benchmarks" / "real_video_data.py"
_spec = importlib.util.spec_from_file_location("real_video_data", _DATA)
assert _spec is not None and _spec.loader is not None
rvd = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rvd)

MARKED = [f for f in rvd.load_marks()["frames"] if f["side"] == "right"]


@pytest.fixture(scope="module")
def frames() -> dict:
    try:
        path = rvd.video_path()
    except FileNotFoundError as exc:  # fail, not skip: the acceptance figures must not vanish silently
        pytest.fail(f"the real box video is missing: {exc}")
    return rvd.read_frames(path, [f["index"] for f in MARKED])


def _errors(frame: dict, image) -> dict[str, float]:
    truth = rvd.truth_mm(frame)
    spec = ScanSpec.model_validate({
        "image": "frame.png", "points": rvd.points_of(frame), "formats": ["csv"],
        "scale": {"kind": "edge", "edge": "width", "length_mm": truth["width"]}})
    try:
        dims = run_scan(spec, image).report["dimensions"]
    except InputError as exc:
        pytest.fail(f"frame {frame['index']}: the engine refused the marks: {exc}")
    return {a: abs(dims[a] / truth[a] - 1) for a in ("height", "depth")}


def test_marks_cover_enough_frames() -> None:
    assert len(MARKED) >= 5
    assert all(len(rvd.points_of(f)) == 7 for f in MARKED)


@pytest.mark.xfail(strict=False, reason="needs the free-focal fit")
def test_known_width_no_focal_within_issue_bounds(frames: dict) -> None:
    errors = {f["index"]: _errors(f, frames[f["index"]]) for f in MARKED}
    for axis in ("height", "depth"):
        median = statistics.median(e[axis] for e in errors.values())
        assert median <= 0.02, f"median {axis} error {median:.1%} over frames {sorted(errors)}"
    worst = {i: max(e.values()) for i, e in errors.items()}
    bad = {i: f"{w:.1%}" for i, w in worst.items() if w > 0.05}
    assert not bad, f"frames over 5 %: {bad}"

"""Issue 20, item 1 through a real worker (Celery process, Redis, SeaweedFS): several views of one
part measured as ONE box (`prismcore.multiview.joint.fit_views`), whole in one task.

* Photo-like renders of one box from three viewpoints (`prismsynth.photo_like_views`): the box
  within its stated 2 sigma and 3 % of the truth; a view whose points mark a deeper box is named
  and left out; views of two image sizes, and an unreadable view, fail their item with the reason.
* The real cookie-box video (OpenCV's box.mp4, `benchmarks/real_video_data.py`) with fit "joint":
  its 12 hand-marked frames as one box, one of them given wrong marks: H and D within 8 % (each
  frame alone scatters more; the joint fit measured +4.1 % / +5.0 % on the 12 good frames), the
  wrong frame named and left out.
"""

from __future__ import annotations

import importlib.util
import json
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from prism_common.public import ResultPublic
from prism_common.records import State

from prismcore.spec import ScanSpec
from prismsynth import PhotoLikeScene, photo_like_views

from .worker_env import Env, encode, worker_env

pytestmark = pytest.mark.slow  # photo-like renders, a real video and joint fits on a real worker

_DATA = Path(__file__).resolve().parents[2] / "benchmarks" / "real_video_data.py"
_spec = importlib.util.spec_from_file_location("real_video_data", _DATA)
assert _spec is not None and _spec.loader is not None
rvd = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rvd)

DIMENSIONS = ("width", "height", "depth")


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    # The service's default visibility timeout (over the task's time limit): a joint fit of the
    # video's frames runs tens of seconds, and is not handed out a second time meanwhile.
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=9,
                    bucket="t-joint", tiles_per_face=1, items_in_flight=2,
                    visibility_timeout_s=300) as made:
        yield made


@pytest.fixture(scope="module")
def scenes() -> list[PhotoLikeScene]:
    return photo_like_views(2, 3)


def _deeper(points: list[list[float]], factor: float) -> list[list[float]]:
    """The points with the second face's far corners pulled out along the depth: a deeper box."""
    c = {f"p{k + 1}": np.asarray(p, dtype=float) for k, p in enumerate(points)}
    c["p5"] = c["p4"] + factor * (c["p5"] - c["p4"])
    c["p7"] = c["p3"] + factor * (c["p7"] - c["p3"])
    return [[float(v) for v in c[f"p{k}"]] for k in range(1, 8)]


def _clicks(scene: PhotoLikeScene) -> list[list[float]]:
    return [[float(x), float(y)] for x, y in scene.click_list()]


def _item(refs: list[str], points: list[list[list[float]]], scene: PhotoLikeScene) -> ScanSpec:
    return ScanSpec.model_validate({
        "views": [{"image": r, "points": p} for r, p in zip(refs, points, strict=True)],
        "scale": {"kind": "edge", "edge": scene.known_edge, "length_mm": scene.known_length_mm}})


def test_views_of_one_box_are_measured_as_one_box(env: Env, scenes: list[PhotoLikeScene]) -> None:
    refs = [env.upload(encode(s.image, ".jpg"), name=f"view{k + 1}.jpg") for k, s in enumerate(scenes)]
    clicks = [_clicks(s) for s in scenes]
    small = cv2.resize(scenes[2].image, (640, 480), interpolation=cv2.INTER_AREA)
    specs = [
        _item(refs, clicks, scenes[0]),
        _item(refs, [clicks[0], _deeper(clicks[1], 1.15), clicks[2]], scenes[0]),
        _item([*refs[:2], env.upload(encode(small), name="small.png")],
              [*clicks[:2], [[x / 2, y / 2] for x, y in clicks[2]]], scenes[0]),
        _item([refs[0], env.upload(b"GIF89a not a photo", name="bad.gif"), refs[2]], clicks, scenes[0]),
    ]
    job = env.wait(env.submit(specs), timeout=300)
    assert job.state == State.completed_with_failures, job
    good, wrong, sizes, unreadable = job.items
    box = scenes[0].box

    assert good.state == State.succeeded, good.error
    result = good.result
    assert result is not None and result.uncertainty is not None and result.joint is not None
    for name in DIMENSIONS:
        true, got, sigma = getattr(box, f"{name}_mm"), result.dimensions[name], result.uncertainty[name]
        assert abs(got - true) <= 2 * sigma + 1e-4, (name, got, true, sigma)  # 1e-4: the rounding
        assert abs(got / true - 1) <= 0.03, (name, got, true)
    assert result.dimensions["unit"] == "mm" and result.points == 0
    assert result.focal_source == "fitted"
    assert result.focal_px == pytest.approx(scenes[0].camera_matrix[0, 0], rel=0.05)
    assert [(v["index"], v["name"]) for v in result.joint["views"]] == [(0, "view 1"), (1, "view 2"),
                                                                        (2, "view 3")]
    assert result.joint["left_out"] == [] and not any("left out" in w for w in result.warnings)
    ResultPublic.model_validate(result.model_dump())  # the public shape holds the record's
    report = json.loads(env.objects.get_bytes(good.outputs["joint"]))
    assert report["dimensions"] == result.dimensions and report["inputs"][1] == {"index": 1, "image": refs[1]}
    assert set(good.outputs) == {"joint"}

    assert wrong.state == State.succeeded, wrong.error
    joint = wrong.result.joint
    assert [o["index"] for o in joint["left_out"]] == [1] and joint["left_out"][0]["name"] == "view 2"
    assert "disagrees with the other views beyond its noise" in joint["left_out"][0]["reason"]
    assert [v["index"] for v in joint["views"]] == [0, 2]
    assert any(w.startswith("view 2 left out: disagrees") for w in wrong.result.warnings)
    for name in DIMENSIONS:
        assert abs(wrong.result.dimensions[name] / getattr(box, f"{name}_mm") - 1) <= 0.03, name

    assert sizes.state == State.failed and not sizes.outputs
    assert sizes.error == ("view 3 (views[2]) is 640x480 px, view 1 1280x960 px: the views of a joint fit "
                           "must come from one camera at one image size"), sizes.error
    assert unreadable.state == State.failed
    assert unreadable.error == "'bad.gif' is a GIF image; supported formats are BMP, PNG, JPEG, TIFF, WebP"
    # Only the reports: nothing stored on the way, nothing for the failed items.
    assert env.keys(job.id) == {"job.json", "items/0/joint.json", "items/1/joint.json"}
    total, done = env.units(job.id)
    assert total == done == 4 * 2  # plan + complete per item


@pytest.fixture(scope="module")
def box_video() -> bytes:
    try:
        return rvd.video_path().read_bytes()
    except FileNotFoundError as exc:  # fail, not skip: the acceptance figures must not vanish silently
        pytest.fail(f"the real box video is missing: {exc}")


def test_a_video_with_fit_joint_is_measured_as_one_box(env: Env, box_video: bytes) -> None:
    frames = rvd.load_marks()["frames"]
    assert len(frames) == 12 and {f["side"] for f in frames} == {"right"}
    wrong = 150
    points = {f["index"]: _deeper(rvd.points_of(f), 1.3) if f["index"] == wrong else rvd.points_of(f)
              for f in frames}
    truth = rvd.truth_mm(frames[0])
    spec = ScanSpec.model_validate({
        "image": env.upload(box_video, name="box.mp4"), "fit": "joint", "side_face": "right",
        "frame_points": points, "scale": {"kind": "edge", "edge": "width", "length_mm": truth["width"]}})
    job = env.wait(env.submit([spec]), timeout=400)
    [item] = job.items
    assert item.state == State.succeeded, item.error
    result = item.result
    assert result is not None and result.joint is not None and result.uncertainty is not None
    assert result.dimensions["width"] == pytest.approx(truth["width"])
    for name in ("height", "depth"):
        assert abs(result.dimensions[name] / truth[name] - 1) <= 0.08, (name, result.dimensions, truth)
    assert [(o["index"], o["name"]) for o in result.joint["left_out"]] == [(wrong, f"frame {wrong}")]
    assert "disagrees with the other views" in result.joint["left_out"][0]["reason"]
    assert [v["index"] for v in result.joint["views"]] == sorted(set(points) - {wrong})
    assert item.frames == [] and set(item.outputs) == {"joint"}  # one box: no per-frame records
    report = json.loads(env.objects.get_bytes(item.outputs["joint"]))
    assert report["video"]["reference"] == spec.image and report["video"]["frame_count"] == 455
    assert env.keys(job.id) == {"job.json", "items/0/joint.json"}

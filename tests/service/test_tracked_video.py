"""A hand-held video whose seven points are marked on one frame (`points_frame`), through a real
worker (Redis, SeaweedFS, Celery): the points tracked to the selected frames and stored as
tracked_points.json beside the results, each frame measured with its own points (or the frames
as ONE box, fit "joint"), and a frame the tracking leaves out named with its reason. The truth
is the renderer's: each frame's exact corners and the box's size. A tracking that fails frees its
frames from the job's cap (the job's next video is still measured); one that would read more
frames than PRISM_TRACKED_MAX_SPAN is refused by the worker for a job that skipped the API; a
re-run finds tracked_points.json stored and measures with it rather than tracking again. At
submit, a marked frame past the video's end, or too far from the selected frames, is refused with
a pointer to points_frame."""

# ruff: noqa: F811 - `client` is test_api's fixture, imported to be used as such
from __future__ import annotations

import functools
import json
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from prism_common.queue import TASK_RUN_JOB
from prism_common.records import State
from prism_common.settings import Settings

from prismcore.spec import ScanSpec
from prismcore.video.tracked import TRACKED_MAX_SPAN
from prismsynth import Box
from prismsynth.video import moving_clip, write_video

from .test_api import ACME, client, make_client  # noqa: F401 (fixtures)
from .worker_env import Env, worker_env

BOX = Box(120.0, 80.0, 60.0)
TRACKED = 16  # frames of the moving camera; then a cut to a dark scene
CUT = 4
MARKED = 8
SELECTED = [0, 4, MARKED, 12, 15, 17]  # 17: after the cut, left out
EDGE = {"kind": "edge", "edge": "width", "length_mm": BOX.width_mm}
POINT_PX = 2.0  # MJPEG-decoded frames against the renderer's exact corners
SIZE_REL = 0.03  # each frame's (and the joint box's) height and depth against the box's
MAX_FRAMES = 10  # the job's cap, PRISM_MAX_FRAMES_PER_JOB
MAX_SPAN = 18  # PRISM_TRACKED_MAX_SPAN: SELECTED reads frames 0-17, 18 frames


@functools.cache
def _clip() -> tuple[bytes, tuple[np.ndarray, ...]]:
    images, truth = moving_clip(BOX, TRACKED, image_size=(640, 360), focal_px=600.0, sway_deg=8.0, seed=0)
    rng = np.random.default_rng(0)
    dark = [rng.integers(0, 60, images[0].shape, dtype=np.uint8) for _ in range(CUT)]
    folder = Path(tempfile.mkdtemp(prefix="tracked-clip-"))
    write_video([*images, *dark], folder / "clip.avi", codec="MJPG", fps=12.0)
    return (folder / "clip.avi").read_bytes(), tuple(truth)


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=13,
                    bucket="t-tracked", tiles_per_face=1, items_in_flight=1, max_frames=MAX_FRAMES,
                    extra_env={"TRACKED_MAX_SPAN": str(MAX_SPAN)}) as made:
        yield made


def _spec(env: Env, fit: str, frames: list[int] = SELECTED, marked: int = MARKED) -> ScanSpec:
    video, truth = _clip()
    points = [[round(float(x), 2), round(float(y), 2)] for x, y in truth[MARKED]]
    return ScanSpec.model_validate({
        "image": env.upload(video, name="handheld.avi"), "points": points, "points_frame": marked,
        "frames": {"indices": frames}, "scale": EDGE, "focal_px": 600.0, "fit": fit,
        "formats": ["csv"]})


def _check_track(env: Env, key: str) -> dict[str, dict]:
    """tracked_points.json: each tracked frame's points against the renderer's, the cut named."""
    doc = json.loads(env.objects.get_bytes(key))
    _, truth = _clip()
    assert sorted(map(int, doc)) == SELECTED
    for index in SELECTED[:-1]:
        entry = doc[str(index)]
        assert "points" in entry, (index, entry)
        worst = float(np.linalg.norm(np.array(entry["points"]) - truth[index], axis=1).max())
        assert worst < POINT_PX, (index, worst)
        assert 0 < entry["quality"]["confidence"] <= 1
    assert "cut" in doc["17"]["reason"]
    return doc


@pytest.mark.parametrize("fit", ["frames", "joint"])
def test_points_marked_on_one_frame_are_tracked_and_measured(env: Env, fit: str) -> None:
    job = env.wait(env.submit([_spec(env, fit)]), timeout=300)
    item = job.items[0]
    assert item.state == State.succeeded, item.error
    assert set(item.outputs) >= {"tracked_points", "joint" if fit == "joint" else "summary"}
    assert item.outputs["tracked_points"].endswith("/items/0/tracked_points.json")
    doc = _check_track(env, item.outputs["tracked_points"])
    tracking = item.result.summary["tracking"]
    assert tracking["points_frame"] == MARKED
    assert tracking["tracked"] == SELECTED[:-1]
    assert tracking["left_out"] == {"17": doc["17"]["reason"]}
    assert f"frame 17 left out by the tracking: {doc['17']['reason']}" in item.result.warnings
    for name in ("height", "depth"):
        assert abs(item.result.dimensions[name] / getattr(BOX, f"{name}_mm") - 1) < SIZE_REL, item.result
    if fit == "joint":
        report = json.loads(env.objects.get_bytes(item.outputs["joint"]))
        assert report["tracking"]["chosen"] and set(report["tracking"]["chosen"]) <= set(SELECTED[:-1])
        assert {v["index"] for v in report["views"]} <= set(report["tracking"]["chosen"])
        assert item.result.uncertainty["height"] > 0
        return
    frames = {f.index: f for f in item.frames}
    assert sorted(frames) == SELECTED
    for index in SELECTED[:-1]:
        assert frames[index].state == State.succeeded, frames[index].error
        for name in ("height", "depth"):
            measured = frames[index].result.dimensions[name]
            assert abs(measured / getattr(BOX, f"{name}_mm") - 1) < SIZE_REL, (index, name, measured)
    assert frames[17].state == State.failed and "left out by the tracking" in frames[17].error
    summary = json.loads(env.objects.get_bytes(item.outputs["summary"]))
    assert summary == item.result.summary
    assert summary["frames"] == {"selected": len(SELECTED), "measured": len(SELECTED) - 1, "failed": 1}


def test_a_marked_frame_past_the_video_is_refused_at_submit(client) -> None:
    video, truth = _clip()
    r = client.post("/v1/uploads", files={"file": ("clip.avi", video)}, headers=ACME)
    assert r.status_code == 201, r.text
    reference = r.json()["reference"]
    points = [[round(float(x), 2), round(float(y), 2)] for x, y in truth[0]]
    item = {"image": reference, "points": points, "frames": {"every": 4}}
    total = TRACKED + CUT
    r = client.post("/v1/jobs", json={"items": [{**item, "points_frame": total}]}, headers=ACME)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/points_frame"
    assert f"points_frame {total} is past the video's end: it has {total} frames (0-{total - 1})" \
        in error["detail"]
    ok = client.post("/v1/jobs", json={"items": [{**item, "points_frame": total - 1}]}, headers=ACME)
    assert ok.status_code == 202, ok.text


def test_a_failed_tracking_frees_its_frames_from_the_jobs_cap(env: Env) -> None:
    # Item 0's frames are all after the cut: nothing can be tracked, the item fails. Its 4
    # frames and item 1's 7 would be 11, over the job's cap of 10, had item 0 kept its claim;
    # items run one at a time (items_in_flight 1), item 0 first.
    lost, kept = [16, 17, 18, 19], [0, 2, 4, 6, 8, 10, 12]
    assert len(lost) + len(kept) > MAX_FRAMES >= len(kept)
    job = env.wait(env.submit([_spec(env, "frames", lost), _spec(env, "frames", kept)]), timeout=300)
    first, second = job.items
    assert first.state == State.failed
    assert first.error.startswith("no frame of 'handheld.avi' could be tracked from frame 8: "), first.error
    assert second.state == State.succeeded, second.error
    assert [f.index for f in second.frames if f.state == State.succeeded] == kept


@pytest.mark.parametrize(("frames", "marked", "read"), [([0, 4], 18, (0, 18)), ([15, 19], 1, (1, 19))])
def test_a_tracking_over_the_span_cap_is_refused_by_the_worker(env: Env, frames: list[int], marked: int,
                                                               read: tuple[int, int]) -> None:
    job = env.wait(env.submit([_spec(env, "frames", frames, marked)]), timeout=120)  # no API check
    [item] = job.items
    lo, hi = read
    assert item.state == State.failed
    assert item.error == (f"points_frame {marked}: tracking the points to the selected frames reads frames "
                          f"{lo}-{hi}, {hi - lo + 1} frames, over the cap of {MAX_SPAN} frames one tracking "
                          "may read: mark the points on a frame nearer the selected ones, or select frames "
                          f"nearer frame {marked} (start_s/end_s or indices)")
    assert not env.objects.exists(f"jobs/{job.id}/items/0/tracked_points.json")  # nothing was tracked


@functools.cache
def _long_clip() -> bytes:
    """301 grey frames: one more than the default span cap (PRISM_TRACKED_MAX_SPAN 300)."""
    grey = np.full((360, 640, 3), 128, np.uint8)
    folder = Path(tempfile.mkdtemp(prefix="tracked-long-"))
    write_video([grey] * 301, folder / "long.avi", codec="MJPG", fps=25.0)
    return (folder / "long.avi").read_bytes()


@pytest.mark.parametrize(("frames", "marked", "refused"), [
    ({"indices": [0]}, 300, True), ({"indices": [0]}, 299, False),
    ({"every": 50}, 0, True),  # frames 0-300: the last selected one is 300
    ({"every": 50, "end_s": 8.0}, 0, False),  # frames 0-150
    ({"start_s": 4.0}, 0, True),  # frames 100-300 and the marked one: 0-300
    ({"sharpest": 2}, 0, False),  # unknown before decoding: the worker checks
])
def test_a_tracking_over_the_span_cap_is_refused_at_submit(client, frames: dict, marked: int,
                                                           refused: bool) -> None:
    r = client.post("/v1/uploads", files={"file": ("long.avi", _long_clip())}, headers=ACME)
    assert r.status_code == 201, r.text
    _, truth = _clip()
    points = [[round(float(x), 2), round(float(y), 2)] for x, y in truth[0]]
    item = {"image": r.json()["reference"], "points": points, "frames": frames, "points_frame": marked}
    r = client.post("/v1/jobs", json={"items": [item]}, headers=ACME)
    if not refused:
        assert r.status_code == 202, r.text
        return
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/points_frame"
    assert "301 frames, over the cap of 300 frames one tracking may read: mark the points on a frame " \
        "nearer the selected ones, or select frames nearer frame" in error["detail"], error


def test_a_rerun_reuses_the_stored_tracking(env: Env) -> None:
    # A re-run of the split's first task (a redelivery, a restart) finds tracked_points.json and
    # does not track again: here one written before the job runs, with frame 4 left out for a
    # reason the tracker never gives and the others at the renderer's corners. The frames are
    # measured with those points, frame 4 fails with that reason: the stored tracking was used.
    _, truth = _clip()
    stored = {str(i): {"points": truth[i].round(3).tolist(), "quality": {"confidence": 1.0}}
              for i in SELECTED[:-1] if i != 4}
    stored["4"] = {"reason": "stored by an earlier run"}
    stored["17"] = {"reason": "a cut"}
    job_id = env.create([_spec(env, "frames")])
    key = f"jobs/{job_id}/items/0/tracked_points.json"
    env.objects.put_json(key, stored)
    env.celery.send_task(TASK_RUN_JOB, (job_id,))
    item = env.wait(job_id, timeout=300).items[0]
    assert item.state == State.succeeded, item.error
    assert json.loads(env.objects.get_bytes(key)) == stored  # not tracked again, not rewritten
    frames = {f.index: f for f in item.frames}
    assert frames[4].state == State.failed
    assert frames[4].error == "frame 4 left out by the tracking: stored by an earlier run"
    assert item.result.summary["tracking"]["tracked"] == [i for i in SELECTED[:-1] if i != 4]
    for index in (0, MARKED, 12, 15):
        assert frames[index].state == State.succeeded, frames[index].error
        points = frames[index].result.reference_points
        got = np.array([points[f"p{k}"] for k in range(1, 8)])
        np.testing.assert_allclose(got, truth[index].round(3), atol=1e-3)


def test_the_services_span_cap_defaults_to_the_engines() -> None:
    # settings.py states the number rather than import the engine's fitting libraries
    assert Settings.model_fields["tracked_max_span"].default == TRACKED_MAX_SPAN

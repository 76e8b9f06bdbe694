"""Video items through a real worker: split once, one task per frame, per-frame outputs and
records, the item's summary over its frames; bad videos and the frame cap fail only their item.
"""

from __future__ import annotations

import json
import statistics
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler
from pathlib import Path

import numpy as np
import pytest
from prism_common.records import State

from prismcore.spec import ScanSpec, frame_folder
from prismsynth import Box, render_clip, write_video

from .tls import https_server, make_cert
from .worker_env import INPUTS_BUCKET, NAMES, Env, encode, spec_for, worker_env

BOX = Box(120.0, 80.0, 60.0)
FRAMES = 6
FPS = 12.0
CAP = 5  # frames per job
FRAME_FILES = {"frame.png", "cloud.csv", "cloud.ply", "preview.ply", "overlay.jpg", "report.json"}


@pytest.fixture(scope="module")
def cert(tmp_path_factory) -> Path:
    return make_cert(tmp_path_factory.mktemp("tls"))


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory, cert) -> Iterator[Env]:
    fetch = {"FETCH_ALLOWED_HOSTS": '["localhost"]', "FETCH_ALLOW_PRIVATE": "true",
             "FETCH_CA_BUNDLE": str(cert / "cert.pem")}
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=5,
                    bucket="t-video", tiles_per_face=4, items_in_flight=2, max_frames=CAP,
                    extra_env=fetch) as made:
        yield made


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> tuple[list, bytes]:
    scenes = render_clip(BOX, FRAMES, seed=3)
    path = Path(tmp_path_factory.mktemp("clip")) / "clip.avi"
    write_video((s.image for s in scenes), path, codec="MJPG", fps=FPS)
    return scenes, path.read_bytes()


def _clicks(scene) -> list[list[float]]:
    return [[float(v) for v in np.rint(scene.points[n])] for n in NAMES]


def _video_spec(reference: str, scenes, **extra) -> ScanSpec:
    common = {"image": reference, "focal_px": scenes[0].focal_px,
              "scale": {"kind": "pinhole", "distance_mm": scenes[0].distance_mm}}
    if "frame_points" not in extra:
        common["points"] = _clicks(scenes[0])  # a fixed camera: frame 0's clicks for every frame
    return ScanSpec.model_validate({**common, **extra})


def test_a_video_is_measured_frame_by_frame_beside_photos_and_bad_videos(env, clip):
    scenes, video = clip
    specs = [_video_spec(env.upload(video, name="clip.avi"), scenes, frames={"every": 2}),
             spec_for(env.upload(encode(scenes[0].image)), scenes[0]),
             _video_spec(env.upload(b"RIFF\x10\x00\x00\x00AVI junk" * 50, name="junk.avi"), scenes,
                         frames={"every": 2})]
    job = env.wait(env.submit(specs), timeout=120)
    assert job.state == State.completed_with_failures and job.progress == 100, job
    video, photo, junk = job.items
    assert (video.state, photo.state, junk.state) == (State.succeeded, State.succeeded, State.failed)
    assert "junk.avi" in junk.error and "/tmp" not in junk.error, junk.error

    assert [f.index for f in video.frames] == [0, 2, 4]
    widths = []
    for frame in video.frames:
        assert frame.state == State.succeeded, frame
        dims = frame.result.dimensions
        for name, true in (("width", BOX.width_mm), ("height", BOX.height_mm), ("depth", BOX.depth_mm)):
            assert abs(dims[name] / true - 1) < 0.02, (frame.index, name, dims)
        widths.append(dims["width"])
        report = json.loads(env.objects.get_bytes(frame.outputs["report"]))
        assert report["dimensions"] == frame.result.dimensions
        # As the CLI's per-frame report: which frame, and when (the clip runs at FPS).
        assert report["frame"] == {"index": frame.index, "time_s": pytest.approx(frame.index / FPS, abs=1e-6)}
    summary = json.loads(env.objects.get_bytes(video.outputs["summary"]))
    assert summary == video.result.summary
    assert summary["selection"] == {"every": 2}
    assert summary["video"]["reference"] == specs[0].image
    assert (summary["video"]["frame_count"], summary["video"]["width"]) == (FRAMES, scenes[0].image.shape[1])
    assert summary["frames"] == {"selected": 3, "measured": 3, "failed": 0}
    assert summary["dimensions"]["width"]["median"] == pytest.approx(statistics.median(widths), abs=1e-6)
    assert summary["dimensions"]["width"]["spread"] == pytest.approx(max(widths) - min(widths), abs=1e-6)
    assert video.result.dimensions["width"] == summary["dimensions"]["width"]["median"]
    assert video.result.points == sum(f.result.points for f in video.frames)

    keys = env.keys(job.id)
    per_frame = {f"items/0/{frame_folder(n)}/{name}" for n in (0, 2, 4) for name in FRAME_FILES}
    assert {k for k in keys if k.startswith("items/0/")} == {
        "items/0/frames.json", "items/0/summary.json"} | per_frame
    assert not any(k.startswith("items/2/") for k in keys)
    total, done = env.units(job.id)
    # video: plan, 3 frames, complete; photo: plan, 2 faces x 2 tiles, complete; junk: plan, complete
    assert total == done == (1 + 3 + 1) + (1 + 2 * 2 + 1) + 2


def test_videos_from_a_bucket_and_an_https_url_are_streamed_and_measured(env, clip, cert):
    scenes, video = clip
    env.objects.client.put_object(Bucket=INPUTS_BUCKET, Key="videos/clip.avi", Body=video)

    class Server(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)  # no Content-Length: the body arrives in parts until it ends
            self.end_headers()
            for start in range(0, len(video), 64 * 1024):
                self.wfile.write(video[start:start + 64 * 1024])

        def log_message(self, *args) -> None:
            pass

    with https_server(cert, Server) as port:
        # Every 3rd frame of each: 4 in all, within the job's cap of CAP.
        specs = [_video_spec(f"s3://{INPUTS_BUCKET}/videos/clip.avi", scenes, frames={"every": 3}),
                 _video_spec(f"https://localhost:{port}/clip.avi", scenes, frames={"every": 3})]
        job = env.wait(env.submit(specs), timeout=120)
    assert job.state == State.succeeded, job
    for item in job.items:
        assert item.state == State.succeeded, item
        assert [f.index for f in item.frames] == [0, 3]
        for name, true in (("width", BOX.width_mm), ("height", BOX.height_mm), ("depth", BOX.depth_mm)):
            assert abs(item.result.dimensions[name] / true - 1) < 0.02, (item.index, name)
    # The same bytes, whichever way they came: the same measurements.
    assert job.items[0].result == job.items[1].result.model_copy(
        update={"summary": {**job.items[1].result.summary, "video": job.items[0].result.summary["video"]}})


def test_per_frame_points_and_a_frame_that_fails_alone(env, clip):
    scenes, video = clip
    points = {i: _clicks(scenes[i]) for i in (1, 3)}
    points[5] = [[5000.0, 5000.0]] * 7  # off the frame: this frame cannot be measured
    job = env.wait(env.submit([_video_spec(env.upload(video), scenes, frame_points=points)]), timeout=120)
    assert job.state == State.succeeded, job
    item = job.items[0]
    assert [(f.index, f.state) for f in item.frames] == [(1, State.succeeded), (3, State.succeeded),
                                                        (5, State.failed)]
    assert item.frames[2].error and not item.frames[2].outputs
    assert item.result.warnings == ["1 of 3 frames could not be measured"]
    assert item.result.summary["failed"][0]["frame"] == 5


def test_the_frame_cap_fails_the_item_that_goes_over_it(env, clip):
    scenes, video = clip
    ref = env.upload(video)
    over = env.wait(env.submit([_video_spec(ref, scenes, frames={})]), timeout=120)  # all 6 > CAP
    assert over.state == State.failed and "over the cap of 5" in over.items[0].error
    # 3 + 3 frames: whichever item claims its frames second goes over the job's cap alone.
    both = env.wait(env.submit([_video_spec(ref, scenes, frames={"every": 2}) for _ in range(2)]),
                    timeout=120)
    states = sorted(item.state for item in both.items)
    assert states == [State.failed, State.succeeded] and both.state == State.completed_with_failures, both
    failed = next(item for item in both.items if item.state == State.failed)
    assert "the job's videos select 6 frames, over the cap of 5 frames per job" in failed.error


def test_a_video_without_a_focal_length_is_measured_with_one_pooled_over_its_frames(env, clip):
    scenes, video = clip
    spec = ScanSpec.model_validate({
        "image": env.upload(video, name="pooled.avi"), "points": _clicks(scenes[0]),
        "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0}, "frames": {"every": 2}})
    job = env.wait(env.submit([spec]), timeout=120)
    item = job.items[0]
    assert item.state == State.succeeded, item.error
    summary = item.result.summary
    assert summary["focal"]["pooled_px"] == pytest.approx(scenes[0].focal_px, rel=0.03)
    assert len(summary["focal"]["frames"]) >= 2
    for frame in item.frames:
        assert frame.state == State.succeeded, frame.error
        assert frame.result.focal_source == "pooled"
        assert frame.result.focal_px == pytest.approx(summary["focal"]["pooled_px"], abs=1e-3)
        assert abs(frame.result.dimensions["depth"] / 60.0 - 1) < 0.02
    assert "focal.json" in {k.rsplit("/", 1)[-1] for k in env.keys(job.id)}

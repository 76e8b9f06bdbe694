"""An uploaded video's probe and frames for the web page: the API (in process) sends
prism.extract_frame to a real worker process and serves what it wrote, on the real Redis and
SeaweedFS. Frames are checked against an independent decode of the same file."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from prism_common.queue import TASK_EXTRACT_FRAME
from prism_common.upload_keys import tenant_hash

from prismsynth import Box, render_clip, write_video

from .pending import app_client, poll, wait_for
from .test_api import ACME, GLOBEX, TestClient, upload
from .worker_env import Env, encode, worker_env

BOX = Box(120.0, 80.0, 60.0)
FRAMES = 5


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=6,
                    bucket="t-upload-frames", tiles_per_face=1, items_in_flight=1) as made:
        yield made


@pytest.fixture(scope="module")
def api(env) -> Iterator[TestClient]:
    with app_client(env.settings) as client:
        yield client


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> tuple[list, bytes, list[np.ndarray]]:
    """The scenes, the MJPEG AVI's bytes, and its frames as OpenCV reads them one after another."""
    scenes = render_clip(BOX, FRAMES, seed=4)
    path = Path(tmp_path_factory.mktemp("clip")) / "clip.avi"
    write_video((s.image for s in scenes), path, codec="MJPG")
    capture, decoded = cv2.VideoCapture(str(path)), []
    while (got := capture.read())[0]:
        decoded.append(cv2.cvtColor(got[1], cv2.COLOR_BGR2RGB))
    capture.release()
    assert len(decoded) == FRAMES
    return scenes, path.read_bytes(), decoded


def _poll(api: TestClient, path: str, timeout: float = 60, headers: dict = ACME):
    return poll(api, path, working="decoding", headers=headers, timeout=timeout)


def _id(reference: str) -> str:
    return reference.removeprefix("upload:")


def test_probe_and_frames_are_the_videos_own(api, env, clip):
    scenes, video, decoded = clip
    upload_id = _id(upload(api, video, name="clip.avi"))
    first = api.get(f"/v1/uploads/{upload_id}/video", headers=ACME)
    assert first.status_code == 202 and first.headers["Retry-After"] == "1"
    r = _poll(api, f"/v1/uploads/{upload_id}/video")
    assert r.status_code == 200, r.text
    assert r.json() == {"id": upload_id, "frame_count": FRAMES, "fps": 25.0, "width": 640, "height": 512,
                        "codec": "MJPG", "duration_s": FRAMES / 25}
    for n in (0, 3, FRAMES - 1):
        r = _poll(api, f"/v1/uploads/{upload_id}/frames/{n}.png")
        assert r.status_code == 200 and r.headers["Content-Type"] == "image/png", r.text
        assert r.headers["Content-Length"] == str(len(r.content))
        frame = cv2.cvtColor(cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR),
                             cv2.COLOR_BGR2RGB)
        assert np.array_equal(frame, decoded[n]), n  # lossless, and exactly frame n
        assert np.abs(frame.astype(int) - scenes[n].image).mean() < 3  # what was encoded, give or take JPEG
    prefix = f"uploads/{tenant_hash('acme')}/{upload_id}"
    frames = {f"{prefix}.frames/frame_{n:06d}.png" for n in (0, 3, FRAMES - 1)}
    assert set(env.objects.list_keys(prefix)) == {prefix, f"{prefix}.video.json", *frames}


def test_polling_sends_one_extraction_and_a_repeat_rewrites_nothing(api, env, clip):
    upload_id = _id(upload(api, clip[1], name="clip.avi"))
    assert _poll(api, f"/v1/uploads/{upload_id}/video").status_code == 200
    runs = env.runs(TASK_EXTRACT_FRAME)
    path = f"/v1/uploads/{upload_id}/frames/2.png"
    answers = [api.get(path, headers=ACME).status_code for _ in range(5)]
    assert answers[0] == 202 and set(answers) <= {200, 202}
    png = _poll(api, path).content
    wait_for(lambda: env.runs(TASK_EXTRACT_FRAME) >= runs + 1)
    key = f"uploads/{tenant_hash('acme')}/{upload_id}.frames/frame_000002.png"
    written = env.objects.client.head_object(Bucket=env.objects.bucket, Key=key)["LastModified"]

    time.sleep(1.1)  # S3 times have 1 s resolution: a rewrite would show
    env.celery.send_task(TASK_EXTRACT_FRAME, (upload_id, 2))  # redelivered, say
    wait_for(lambda: env.runs(TASK_EXTRACT_FRAME) >= runs + 2)
    assert env.runs(TASK_EXTRACT_FRAME) == runs + 2  # the polls above sent one task, not five
    assert env.objects.client.head_object(Bucket=env.objects.bucket, Key=key)["LastModified"] == written
    assert api.get(path, headers=ACME).content == png


def test_frames_out_of_range(api, clip):
    upload_id = _id(upload(api, clip[1], name="clip.avi"))
    # Asked before the frame count is known: the worker probes, and then the count answers.
    r = _poll(api, f"/v1/uploads/{upload_id}/frames/{FRAMES}.png")
    assert r.status_code == 404, r.text
    assert r.json()["detail"] == f"no frame {FRAMES}: upload {upload_id} has {FRAMES} frames (0-{FRAMES - 1})"
    assert api.get(f"/v1/uploads/{upload_id}/frames/999999.png", headers=ACME).status_code == 404
    assert api.get(f"/v1/uploads/{upload_id}/frames/-1.png", headers=ACME).status_code == 422
    assert api.get(f"/v1/uploads/{upload_id}/frames/one.png", headers=ACME).status_code == 422


@pytest.mark.parametrize(("data", "name", "words"), [
    (None, "box.png", "'box.png' is not a video (AVI, MP4, MOV or MKV): it starts with b'\\x89PNG"),
    (b"RIFF\x10\x00\x00\x00AVI junk" * 50, "junk.avi", "'junk.avi' is a truncated or corrupt AVI video"),
], ids=["photo", "corrupt-avi"])
def test_not_a_video_is_refused_with_the_reason(api, env, clip, data, name, words):
    data = data if data is not None else encode(clip[0][0].image)
    upload_id = _id(upload(api, data, name=name))
    r = _poll(api, f"/v1/uploads/{upload_id}/video")
    assert r.status_code == 422 and r.json()["detail"].startswith(words), r.text
    assert "/tmp" not in r.json()["detail"]
    runs = env.runs(TASK_EXTRACT_FRAME)
    frame = api.get(f"/v1/uploads/{upload_id}/frames/1.png", headers=ACME)  # refused at once
    assert frame.status_code == 422 and frame.json()["detail"] == r.json()["detail"]
    assert env.runs(TASK_EXTRACT_FRAME) == runs


def test_an_upload_whose_file_is_gone_is_refused_with_the_reason(api, env, clip):
    # A name of its own: the same file under the same name is the upload other tests decoded.
    upload_id = _id(upload(api, clip[1], name="gone.avi"))
    env.objects.client.delete_object(Bucket=env.objects.bucket,
                                     Key=env.store.get_upload(upload_id)["key"])
    r = _poll(api, f"/v1/uploads/{upload_id}/video")
    assert r.status_code == 422 and r.json()["detail"] == "'gone.avi' is no longer stored: upload it again"


def test_another_tenants_upload_is_not_there(api, env, clip):
    upload_id = _id(upload(api, clip[1], name="theirs.avi"))  # not the upload other tests decoded
    for path in (f"/v1/uploads/{upload_id}/video", f"/v1/uploads/{upload_id}/frames/0.png"):
        r = api.get(path, headers=GLOBEX)
        assert r.status_code == 404 and r.json()["detail"] == f"no upload {upload_id!r}", r.text
        assert api.get(path).status_code == 401
    assert not env.redis.exists(f"prism:upload:{upload_id}:extract:0")  # nothing was sent for them
    unknown = api.get(f"/v1/uploads/{'0' * 32}/video", headers=ACME)
    assert unknown.status_code == 404 and unknown.json()["detail"] == f"no upload {'0' * 32!r}"
    assert _poll(api, f"/v1/uploads/{upload_id}/video").status_code == 200  # the owner's, all along

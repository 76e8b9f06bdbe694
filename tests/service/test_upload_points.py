"""The web page's "Find points": ``GET /v1/uploads/{id}/points`` (the API in process) sends
prism.find_points to a real worker process, which searches the upload as a job decodes it and
stores what it found; on the real Redis and SeaweedFS. The truth is the renderer's projection of
the box's corners (`prismsynth.scenes`); the search names the faces its own way, so each point
found is matched to its nearest true corner."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from prism_common.queue import TASK_FIND_POINTS
from prism_common.upload_keys import tenant_hash

from prism_worker.upload_points import found_document
from prismcore.io.images import load_image
from prismcore.locate.search import CONFIDENCE_MIN, find_points
from prismsynth import Box, render_clip, write_video
from prismsynth.scenes import clutter_scene, empty_scene, two_box_scene

from .pending import app_client, poll, wait_for
from .test_api import ACME, GLOBEX, TestClient, upload
from .worker_env import Env, encode, worker_env

SIZE = (640, 512)  # small photos: the search stays cheap


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=10,
                    bucket="t-upload-points", tiles_per_face=1, items_in_flight=1) as made:
        yield made


@pytest.fixture(scope="module")
def api(env) -> Iterator[TestClient]:
    with app_client(env.settings) as client:
        yield client


def _poll(api: TestClient, path: str, timeout: float = 120):
    return poll(api, path, working="searching", headers=ACME, timeout=timeout)


def _id(reference: str) -> str:
    return reference.removeprefix("upload:")


def _worst(points: dict[str, list[float]], corners: np.ndarray) -> tuple[float, int]:
    """Worst distance (px) of a found point to its nearest true corner; corners hit."""
    hit, worst = set(), 0.0
    for xy in points.values():
        d = np.linalg.norm(corners - np.asarray(xy), axis=1)
        hit.add(int(np.argmin(d)))
        worst = max(worst, float(d.min()))
    return worst, len(hit)


def test_a_box_is_found_within_3_px_and_polling_sends_one_search(api, env):
    scene = clutter_scene(0, image_size=SIZE)
    upload_id = _id(upload(api, encode(scene.image), name="scene.png"))
    path = f"/v1/uploads/{upload_id}/points"
    runs = env.runs(TASK_FIND_POINTS)
    first = api.get(path, headers=ACME)
    assert first.status_code == 202 and first.headers["Retry-After"] == "1", first.text
    r = _poll(api, path)
    assert r.status_code == 200, r.text
    found = r.json()
    assert found["reason"] is None and found["warnings"] == []
    assert found["confidence"] >= CONFIDENCE_MIN
    assert (found["id"], found["frame"], found["hint"]) == (upload_id, None, None)
    assert (found["width"], found["height"]) == SIZE
    assert sorted(found["points"]) == ["p1", "p2", "p3", "p4", "p5", "p6", "p7"]
    worst, corners = _worst(found["points"], scene.vertices_px)
    assert worst <= 3.0, found
    assert corners == 6  # P4 is P1 or P2; the other six are six corners
    assert found["side_face"] in ("right", "left", "top")
    assert len(found["faces"]) >= 2 and all(len(q) == 4 for q in found["faces"])
    # Many polls, one search: the worker ran it once (its run is counted as the task returns,
    # just after the answer is stored), and polls now are served from the store.
    wait_for(lambda: env.runs(TASK_FIND_POINTS) >= runs + 1)
    assert all(api.get(path, headers=ACME).json() == found for _ in range(3))
    assert env.runs(TASK_FIND_POINTS) == runs + 1
    key = f"uploads/{tenant_hash('acme')}/{upload_id}.points/photo.json"
    assert env.objects.exists(key)


def test_a_search_that_gave_up_is_said_once_then_searched_again(api, env):
    scene = clutter_scene(0, image_size=SIZE)
    upload_id = _id(upload(api, encode(scene.image), name="scene.png"))
    path = f"/v1/uploads/{upload_id}/points"
    assert _poll(api, path).status_code == 200
    key = f"uploads/{tenant_hash('acme')}/{upload_id}.points/photo.json"
    # What the worker stores when the search's task ran out of retries (search_failed): a
    # cause that may pass, unlike a photo that does not decode.
    env.objects.put_json(key, {"error": "the point search failed: the object store was unreachable",
                               "retry": True})
    gave_up = api.get(path, headers=ACME)
    assert gave_up.status_code == 503 and gave_up.headers["Retry-After"] == "1", gave_up.text
    assert gave_up.json()["detail"] == ("the point search failed: the object store was unreachable; "
                                        "ask again to search again")
    assert not env.objects.exists(key)
    runs = env.runs(TASK_FIND_POINTS)
    # Sent again at once: the first search's claim (30 s) is released with the answer.
    assert api.get(path, headers=ACME).status_code == 202
    wait_for(lambda: env.runs(TASK_FIND_POINTS) >= runs + 1)
    again = _poll(api, path)
    assert again.status_code == 200 and again.json()["reason"] is None, again.text


def test_no_box_is_refused_with_the_reason(api):
    empty = empty_scene(0, image_size=SIZE)  # clutter and no box
    upload_id = _id(upload(api, encode(empty), name="empty.png"))
    r = _poll(api, f"/v1/uploads/{upload_id}/points")
    assert r.status_code == 200, r.text
    found = r.json()
    search = find_points(empty)  # the engine's own answer: passed on as it is
    assert not search.ok and found["reason"] == search.reason and found["reason"]
    assert found["points"] is None and found["side_face"] is None and found["faces"] == []


def test_a_hint_chooses_one_of_two_boxes(api):
    image, boxes = two_box_scene(0)  # at 1280x1024 the two boxes are equally likely
    upload_id = _id(upload(api, encode(image), name="two.png"))
    r = _poll(api, f"/v1/uploads/{upload_id}/points")
    assert r.status_code == 200 and r.json()["reason"].startswith("2 candidate boxes"), r.text
    assert r.json()["points"] is None
    x, y = boxes[1].mean(axis=0)
    r = _poll(api, f"/v1/uploads/{upload_id}/points?hint={x:.2f},{y:.2f}")
    assert r.status_code == 200, r.text
    found = r.json()
    assert found["hint"] == [round(x), round(y)] and found["reason"] is None
    worst, corners = _worst(found["points"], boxes[1])
    assert worst <= 3.0 and corners == 6, found


def test_a_videos_frame_is_searched_as_the_page_shows_it(api, env, tmp_path: Path):
    scenes = render_clip(Box(120.0, 80.0, 60.0), 3, seed=4)
    write_video((s.image for s in scenes), tmp_path / "clip.avi", codec="MJPG")
    upload_id = _id(upload(api, (tmp_path / "clip.avi").read_bytes(), name="clip.avi"))
    r = api.get(f"/v1/uploads/{upload_id}/points", headers=ACME)
    assert r.status_code == 422 and r.json()["errors"][0]["parameter"] == "frame", r.text
    r = _poll(api, f"/v1/uploads/{upload_id}/points?frame=1")
    assert r.status_code == 200, r.text
    found = r.json()
    assert found["frame"] == 1, found
    # The frame searched is the frame the page shows (decoded once, by extract_frame): the
    # answer is the engine's on that very PNG.
    png = api.get(f"/v1/uploads/{upload_id}/frames/1.png", headers=ACME)
    assert png.status_code == 200, png.text
    assert found == {"id": upload_id, "frame": 1, "hint": None,
                     **found_document(find_points(load_image(png.content)), 640, 512)}
    # A frame past the end is refused at once (the upload's probe counted the frames): no search.
    past = api.get(f"/v1/uploads/{upload_id}/points?frame=3", headers=ACME)
    assert past.status_code == 422 and past.json()["errors"][0]["parameter"] == "frame", past.text
    assert past.json()["detail"] == f"upload {upload_id} has 3 frames (0-2): no frame 3"
    assert not env.redis.keys(f"prism:upload:{upload_id}:points:frame_000003*")


@pytest.mark.parametrize(("query", "parameter", "detail"), [
    ("hint=abc", "hint", None),
    ("hint=1,2,3", "hint", None),
    ("hint=1e999,4", "hint", "hint '1e999,4' is not x,y (pixels, e.g. 320,240)"),
    ("hint=640,10", "hint", "hint '640,10' is outside the 640x512 image"),
    ("hint=-1,10", "hint", "hint '-1,10' is outside the 640x512 image"),
    ("frame=0", "frame", None),
    ("frame=-1", "frame", None),
])
def test_bad_input_is_a_problem_naming_the_parameter(api, env, query, parameter, detail):
    upload_id = _id(upload(api, encode(empty_scene(1, image_size=SIZE)), name="bad.png"))
    r = api.get(f"/v1/uploads/{upload_id}/points?{query}", headers=ACME)
    assert r.status_code == 422, r.text
    problem = r.json()
    assert problem["type"] == "https://prismcloud.dev/problems/validation"
    assert problem["errors"][0]["parameter"] == parameter, problem
    if detail is not None:
        assert problem["detail"] == detail
    # Nothing was sent (no claim: the run count may still take in an earlier test's search).
    assert not env.redis.keys(f"prism:upload:{upload_id}:points:*")


def test_another_tenants_upload_is_not_there(api, env):
    upload_id = _id(upload(api, encode(empty_scene(2, image_size=SIZE)), name="theirs.png"))
    path = f"/v1/uploads/{upload_id}/points"
    r = api.get(path, headers=GLOBEX)
    assert r.status_code == 404 and r.json()["detail"] == f"no upload {upload_id!r}", r.text
    assert api.get(path).status_code == 401
    assert not env.redis.keys(f"prism:upload:{upload_id}:points:*")  # nothing was sent for them


def test_a_hint_off_any_image_is_a_problem_when_the_size_is_unknown(api, env):
    # A damaged video is kept with no size in its probe: the hint is still bounded (a huge one
    # once made an object key too long to store, a 500).
    upload_id = _id(upload(api, b"RIFF\x10\x00\x00\x00AVI junk" * 50, name="junk.avi"))
    for hint in ("1e100,1e100", "-3,4"):
        r = api.get(f"/v1/uploads/{upload_id}/points?frame=0&hint={hint}", headers=ACME)
        assert r.status_code == 422 and r.json()["errors"][0]["parameter"] == "hint", r.text
        assert r.json()["detail"] == f"hint {hint!r} is outside any image", r.text
    # Nothing was sent (no claim: the run count may still take in an earlier test's search).
    assert not env.redis.keys(f"prism:upload:{upload_id}:points:*")

"""The whole service, for real: the API under uvicorn, a Celery worker process, redis-server
and SeaweedFS, all on loopback. Jobs go in over HTTP and results come out through the
presigned URLs, as a factory system would use it.
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Iterator

import cv2
import httpx
import laspy
import numpy as np
import pytest
import redis
from plyfile import PlyData
from prism_common.public import JobPublic

from prism_cli.client import ApiClient
from prism_cli.stack import ManagedProcess, start_api, start_worker
from prismcore import run_scan
from prismcore.io.images import load_image
from prismcore.report import report_dict
from prismcore.spec import frame_folder
from prismsynth import Box, render_clip, render_oblique_view, write_video

from .conftest import API_KEYS
from .servers import service_env
from .worker_env import as_stored, wait_no_task

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
ACME = {"X-API-Key": API_KEYS["acme"]}
GLOBEX = {"X-API-Key": API_KEYS["globex"]}


class Stack:
    def __init__(self, api: ManagedProcess, worker: ManagedProcess, env: dict, tmp) -> None:
        self.api, self.worker, self.env, self.tmp = api, worker, env, tmp
        self.http = httpx.Client(base_url=f"http://127.0.0.1:{api.port}", timeout=30)

    def upload(self, data: bytes, name: str = "box.jpg", headers=ACME) -> str:
        r = self.http.post("/v1/uploads", files={"file": (name, data)}, headers=headers)
        assert r.status_code in (200, 201), r.text  # 200: the same content again
        return r.json()["reference"]

    def submit(self, items: list[dict], headers=ACME, **extra) -> httpx.Response:
        return self.http.post("/v1/jobs", json={"items": items, **extra}, headers=headers)

    def wait(self, job_id: str, timeout: float = 120, headers=ACME) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            job = self.http.get(f"/v1/jobs/{job_id}", headers=headers).json()
            if job["state"] in ("succeeded", "completed_with_failures", "failed", "cancelled"):
                return job
            time.sleep(0.25)
        raise AssertionError(f"job {job_id} not final after {timeout} s: {job}\n"
                             f"{self.worker.log[-3000:]}")


@pytest.fixture(scope="module")
def stack(redis_server, s3_server, tmp_path_factory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("stack")
    env = service_env(redis_server.port, s3_server.port, db=1, bucket="stack-e2e",
                      WEBHOOK_ALLOWED_HOSTS='["127.0.0.1"]', WEBHOOK_ALLOW_PRIVATE="true",
                      TILES_PER_FACE="4", VISIBILITY_TIMEOUT_S="10",
                      # A SIGKILL can take a message along (a claimed item not yet sent, or one
                      # popped by the dying worker): the watchdog redoes it within the test's wait.
                      JOB_STALL_TIMEOUT_S="15", WATCHDOG_INTERVAL_S="3")
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=2)
    stack = Stack(api, worker, env, tmp)
    yield stack
    stack.http.close()
    worker.stop()
    api.stop()


@pytest.fixture(scope="module")
def scene():
    return render_oblique_view(BOX, seed=1)


def _jpeg(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, 92])
    assert ok
    return data.tobytes()


def _item(reference: str, scene, **extra) -> dict:
    return {"image": reference, "points": [list(map(round, scene.points[n])) for n in NAMES],
            "focal_px": scene.focal_px,
            "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}, **extra}


def test_two_image_batch_outputs_download_and_match_the_engine(stack, scene):
    photo = _jpeg(scene.image)
    second = _jpeg(render_oblique_view(Box(90, 140, 45), seed=4).image)
    scene2 = render_oblique_view(Box(90, 140, 45), seed=4)
    # The first item asks for the compact outputs (LAZ and glb: it has a scale), the second
    # gets the service's default (CSV and PLY).
    r = stack.submit([_item(stack.upload(photo), scene, formats=["laz", "glb"]),
                      _item(stack.upload(second), scene2)],
                     client_reference="batch-1")
    assert r.status_code == 202, r.text
    assert r.headers["Location"].endswith(f"/v1/jobs/{r.json()['id']}")
    job = stack.wait(r.json()["id"])
    assert job["state"] == "succeeded" and job["progress"] == 100, job
    assert job["client_reference"] == "batch-1"
    for item, box in zip(job["items"], (BOX, Box(90, 140, 45)), strict=True):
        dims = item["result"]["dimensions"]
        assert abs(dims["width"] / box.width_mm - 1) < 0.02, dims
        assert abs(dims["depth"] / box.depth_mm - 1) < 0.02, dims
    # The service's result is exactly the engine's own on the same input (as stored: its spacing).
    first, other = job["items"]
    assert set(first["downloads"]) == {"laz", "glb", "preview", "overlay", "report"}
    assert set(other["downloads"]) == {"csv", "ply", "preview", "overlay", "report"}
    las = laspy.read(io.BytesIO(httpx.get(first["downloads"]["laz"]).content))
    report = httpx.get(first["downloads"]["report"]).json()
    local = run_scan(as_stored(_item("x", scene)), load_image(photo))
    assert report["points"] == report_dict(local.report)["points"] == las.header.point_count
    assert report["dimensions"] == report_dict(local.report)["dimensions"]
    # LAS's axes written out here (metres, Z up: x, z, -y), to its 0.1 mm grid.
    p = local.cloud.points.astype(np.float64)
    np.testing.assert_allclose(np.column_stack([las.x, las.y, las.z]),
                               np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]) / 1000,
                               rtol=0, atol=0.5e-4 + 1e-9)
    rgb = np.column_stack([las.red, las.green, las.blue]) // 257
    np.testing.assert_array_equal(rgb, local.cloud.colors)
    csv = np.loadtxt(io.BytesIO(httpx.get(other["downloads"]["csv"]).content), delimiter=",")
    ply = PlyData.read(io.BytesIO(httpx.get(other["downloads"]["ply"]).content))["vertex"]
    local = run_scan(as_stored(_item("x", scene2)), load_image(second))
    assert other["result"]["points"] == report_dict(local.report)["points"] == csv.shape[0] == ply.count
    np.testing.assert_array_equal(np.column_stack([ply["x"], ply["y"], ply["z"]]),
                                  local.cloud.points)
    # The overlay is a JPEG, served under its name and under the one it had as a PNG (old links).
    picture = httpx.get(other["downloads"]["overlay"]).content
    assert picture[:3] == b"\xff\xd8\xff"
    for route in ("overlay.jpg", "overlay.png"):
        r = stack.http.get(f"/v1/jobs/{job['id']}/items/1/{route}", headers=ACME)
        assert r.status_code == 200 and r.content == picture and r.headers["Content-Type"] == "image/jpeg"


def test_idempotent_submit(stack, scene):
    items = [_item(stack.upload(_jpeg(scene.image)), scene)]
    headers = {**ACME, "Idempotency-Key": "order-42"}
    first = stack.http.post("/v1/jobs", json={"items": items}, headers=headers)
    again = stack.http.post("/v1/jobs", json={"items": items}, headers=headers)
    assert first.status_code == again.status_code == 202
    assert first.json()["id"] == again.json()["id"]
    other = stack.http.post("/v1/jobs", json={"items": items * 2}, headers=headers)
    assert other.status_code == 409


def test_failing_item_beside_a_good_one(stack, scene):
    # Whole, its header (and so its size) reads, its pixels do not: the item fails, not the upload.
    photo = cv2.imencode(".png", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR))[1].tobytes()
    bad = stack.upload(photo[:200] + bytes(b ^ 0x5A for b in photo[200:400]) + photo[400:], name="bad.png")
    job = stack.wait(stack.submit([_item(bad, scene),
                                   _item(stack.upload(_jpeg(scene.image)), scene)]).json()["id"])
    assert job["state"] == "completed_with_failures" and job["items_failed"] == 1
    failed, good = job["items"]
    assert (failed["state"] == "failed" and "bad.png" in failed["error"]) or "corrupt" in failed["error"]
    assert good["state"] == "succeeded" and good["downloads"]


def test_cancel_stops_a_job_and_tells_the_truth(stack, scene):
    ref = stack.upload(_jpeg(scene.image))
    job_id = stack.submit([_item(ref, scene) for _ in range(12)]).json()["id"]
    deadline = time.monotonic() + 60
    while not any(i["state"] == "succeeded" for i in stack.http.get(
            f"/v1/jobs/{job_id}", headers=ACME).json()["items"]):
        assert time.monotonic() < deadline
        time.sleep(0.1)
    cancelled = stack.http.post(f"/v1/jobs/{job_id}/cancel", headers=ACME)
    assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled"
    # The tasks in flight reach their next step and stop: none of the job's is left in the
    # broker, waited for (a fixed 3 s, on a loaded machine, read an item whose task was still
    # finishing, and the job changed after).
    broker = redis.Redis.from_url(stack.env["PRISM_REDIS_URL"], decode_responses=True)
    wait_no_task(broker, job_id)
    job = stack.http.get(f"/v1/jobs/{job_id}", headers=ACME).json()
    states = [item["state"] for item in job["items"]]
    assert job["state"] == "cancelled"
    assert set(states) <= {"succeeded", "cancelled"}, states
    done = states.count("succeeded")
    assert 1 <= done < 12
    # Progress counts finished work only: never 100 for a job that stopped part way.
    assert job["progress"] < 100
    time.sleep(1)
    wait_no_task(broker, job_id)  # nothing was sent after the cancel either
    broker.close()
    later = stack.http.get(f"/v1/jobs/{job_id}", headers=ACME).json()
    assert [item["state"] for item in later["items"]] == states  # nothing runs on after the cancel
    assert later["progress"] == job["progress"]


def test_keys_are_isolated(stack, scene):
    job_id = stack.submit([_item(stack.upload(_jpeg(scene.image)), scene)]).json()["id"]
    assert stack.http.get(f"/v1/jobs/{job_id}", headers=GLOBEX).status_code == 404
    assert stack.http.post(f"/v1/jobs/{job_id}/cancel", headers=GLOBEX).status_code == 404
    listed = stack.http.get("/v1/jobs", headers=GLOBEX).json()["jobs"]
    assert job_id not in [j["id"] for j in listed]
    assert stack.http.get(f"/v1/jobs/{job_id}").status_code == 401
    assert stack.http.get(f"/v1/jobs/{job_id}", headers={"X-API-Key": "nope"}).status_code == 401
    stack.wait(job_id)


def test_a_video_through_the_api_and_the_cli_client(stack, tmp_path):
    scenes = render_clip(Box(120.0, 80.0, 60.0), 4, seed=5)
    write_video((s.image for s in scenes), tmp_path / "clip.mp4", codec="mp4v")
    ref = stack.upload((tmp_path / "clip.mp4").read_bytes(), name="clip.mp4")
    r = stack.submit([_item(ref, scenes[0], frames={"every": 2})])
    assert r.status_code == 202, r.text
    job = stack.wait(r.json()["id"])
    assert job["state"] == "succeeded", job
    item = job["items"][0]
    assert [f["index"] for f in item["frames"]] == [0, 2]
    assert set(item["downloads"]) == {"summary"}
    summary = httpx.get(item["downloads"]["summary"]).json()
    assert summary == item["result"]["summary"] and summary["frames"]["measured"] == 2
    assert abs(item["result"]["dimensions"]["depth"] / 60.0 - 1) < 0.02

    client = ApiClient(str(stack.http.base_url), API_KEYS["acme"])
    try:
        saved = client.download(JobPublic.model_validate(job), tmp_path / "out")
    finally:
        client.close()
    names = {p.relative_to(tmp_path / "out").as_posix() for p in saved}
    assert names == {"item-0/summary.json"} | {f"item-0/{frame_folder(n)}/{f}" for n in (0, 2) for f in
                                               ("cloud.csv", "cloud.ply", "preview.ply", "overlay.jpg",
                                                                "report.json")}  # the defaults
    report = json.loads((tmp_path / "out/item-0/frame_000002/report.json").read_text())
    assert report["dimensions"] == item["frames"][1]["result"]["dimensions"]


def test_worker_killed_mid_job_still_finishes_without_duplicates(stack, scene):
    ref = stack.upload(_jpeg(scene.image))
    job_id = stack.submit([_item(ref, scene) for _ in range(6)]).json()["id"]
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        job = stack.http.get(f"/v1/jobs/{job_id}", headers=ACME).json()
        if job["progress"] > 5:
            break
        time.sleep(0.1)
    stack.worker.kill()  # SIGKILL: tasks in flight are lost with their process
    stack.worker.start()
    job = stack.wait(job_id, timeout=180)
    assert job["state"] == "succeeded", job
    assert all(item["state"] == "succeeded" for item in job["items"])
    points = {item["result"]["points"] for item in job["items"]}
    assert len(points) == 1  # six identical items, one identical result each

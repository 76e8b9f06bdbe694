"""The Celery worker for real: a `celery worker` process (2 prefork children) on the test
Redis and SeaweedFS, fed jobs through the job store and the broker as the API feeds it.
"""

from __future__ import annotations

import base64
import io
import json
import time
import uuid
from collections.abc import Iterator

import numpy as np
import pytest
from plyfile import PlyData
from prism_common.metrics import read_task_durations
from prism_common.queue import QUEUE_SCANS, TASK_PLAN_ITEM, TASK_RUN_JOB, TASK_SCAN_TILE, queue_lists
from prism_common.records import State

from prism_worker.artifacts import dumps_plan, loads_plan, pack_tile, plan_tiles, tile_id, unpack_tile
from prism_worker.broker import UNACKED_HASH
from prismcore import ScanSpec, finish_scan, plan_scan, run_scan
from prismcore.io.images import load_image
from prismcore.outputs.writers import write_csv
from prismcore.report import report_dict
from prismcore.scan.colour_scan import merge_bands, row_tiles, scan_band
from prismsynth import Box, CameraExif, Realism, Style, render_oblique_view

from .worker_env import INPUTS_BUCKET, Env, encode, spec_for, worker_env

TILES_PER_FACE = 4
# Short enough for the kill test's lost message to be found and redone within its wait.
STALL_TIMEOUT_S = 12


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    # One item at a time per job: the second item only starts if the first one refills.
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=2,
                    bucket="t-worker", tiles_per_face=TILES_PER_FACE, items_in_flight=1,
                    stall_timeout_s=STALL_TIMEOUT_S) as made:
        yield made


@pytest.fixture(scope="module")
def scene():
    return render_oblique_view(Box(120.0, 80.0, 60.0), seed=1)


def _item_files(i: int, tile_names: list[str]) -> set[str]:
    return {f"items/{i}/{name}" for name in ("front", "plan.json", "cloud.csv", "cloud.ply",
                                             "preview.ply", "overlay.jpg", "report.json")} | {
        f"items/{i}/tiles/{t}.npz" for t in tile_names}


def _tile_names(spec: ScanSpec, image: np.ndarray) -> list[str]:
    plan = plan_scan(spec, image)
    return [f"{face}-{r0}-{r1}" for face, r0, r1 in plan_tiles(plan, TILES_PER_FACE)]


# -- in process: what passes between the tasks is exact ---------------------------------------
def test_plan_json_and_packed_tiles_reproduce_the_engine_exactly(scene):
    image = load_image(encode(scene.image))
    spec = spec_for("upload:0", scene)
    plan, extra = loads_plan(dumps_plan(plan_scan(spec, image), tiles=[["front", 0, 1]]))
    assert extra == {"tiles": [["front", 0, 1]]}
    scans = []
    for face in plan.faces:
        bands = [unpack_tile(pack_tile(*scan_band(image, face, r0, r1)))
                 for r0, r1 in row_tiles(face, TILES_PER_FACE)]
        scans.append(merge_bands(face, bands))
    tiled, local = finish_scan(plan, [image], scans), run_scan(spec, image)
    np.testing.assert_array_equal(tiled.cloud.points, local.cloud.points)
    np.testing.assert_array_equal(tiled.cloud.colors, local.cloud.colors)
    assert {k: v for k, v in report_dict(tiled.report).items() if k != "timings_ms"} == {
        k: v for k, v in report_dict(local.report).items() if k != "timings_ms"}


# -- through the worker ------------------------------------------------------------------------
def test_two_item_job_succeeds_and_matches_the_engine(env, scene, tmp_path):
    second = render_oblique_view(Box(90.0, 140.0, 45.0), seed=4)
    photo = encode(scene.image)
    env.objects.client.put_object(Bucket=INPUTS_BUCKET, Key="photos/second.jpg",
                                  Body=encode(second.image, ".jpg"))
    specs = [spec_for(env.upload(photo), scene, csv={"header": True}),
             spec_for(f"s3://{INPUTS_BUCKET}/photos/second.jpg", second, formats=["ply"], ply_ascii=True)]
    started = time.monotonic()
    job_id = env.submit(specs, client_reference="batch-1")
    job = env.wait(job_id)
    elapsed = time.monotonic() - started
    print(f"\ntwo-item job (1280x1024, 8 tiles each, 1 item in flight): {elapsed:.2f} s")
    assert job.state == State.succeeded and job.progress == 100, job
    assert [item.state for item in job.items] == [State.succeeded, State.succeeded]
    total, done = env.units(job_id)
    assert total == done == 2 * (2 * TILES_PER_FACE + 2)  # plan + tiles + complete, per item
    for item, box in zip(job.items, (Box(120, 80, 60), Box(90, 140, 45)), strict=True):
        assert abs(item.result.dimensions["width"] / box.width_mm - 1) < 0.02

    first, other = job.items
    assert first.outputs == {kind: f"jobs/{job_id}/items/0/{name}" for kind, name in
                             (("csv", "cloud.csv"), ("ply", "cloud.ply"), ("preview", "preview.ply"),
                              ("overlay", "overlay.jpg"), ("report", "report.json"))}
    assert set(other.outputs) == {"ply", "preview", "overlay", "report"}  # the formats the spec asked for
    names = _tile_names(specs[0], load_image(photo))
    assert len(names) == 2 * TILES_PER_FACE
    assert _item_files(0, names) <= env.keys(job_id)
    assert "items/1/cloud.csv" not in env.keys(job_id) and "job.json" in env.keys(job_id)
    assert json.loads(env.objects.get_bytes(f"jobs/{job_id}/job.json"))["state"] == "succeeded"

    # The tiled result is exactly the engine's own on the same bytes.
    local = run_scan(spec_for("x", scene, csv={"header": True}), load_image(photo))
    report = json.loads(env.objects.get_bytes(first.outputs["report"]))
    assert report["points"] == report_dict(local.report)["points"] == first.result.points
    assert report["dimensions"] == report_dict(local.report)["dimensions"]
    csv = env.objects.get_bytes(first.outputs["csv"])
    expected = io.BytesIO()
    write_csv(expected, local.cloud.points, header=True)
    assert csv == expected.getvalue()
    assert np.loadtxt(io.BytesIO(csv), delimiter=",", skiprows=1).shape == (report["points"], 3)
    (tmp_path / "cloud.ply").write_bytes(env.objects.get_bytes(first.outputs["ply"]))
    ply = PlyData.read(tmp_path / "cloud.ply")["vertex"]  # from a file: from BytesIO is slow
    np.testing.assert_array_equal(np.column_stack([ply["x"], ply["y"], ply["z"]]), local.cloud.points)
    head, body = env.objects.get_bytes(other.outputs["ply"]).split(b"end_header\n")
    assert b"format ascii 1.0" in head and f"element vertex {other.result.points}".encode() in head
    assert np.loadtxt(io.BytesIO(body)).shape == (other.result.points, 6)  # x y z r g b

    durations = read_task_durations(env.redis)
    assert durations["prism.scan_tile"]["count"] >= 16 and durations["prism.finish_item"]["count"] >= 2


def test_each_pool_process_lets_opencv_use_one_thread(env):
    # The pool is the worker's parallelism; OpenCV's threads on top of it spent CPU on handing
    # work between threads (PRISM_ENGINE_THREADS, 1 unless set).
    lines = [line for line in env.worker.log.splitlines() if "OpenCV uses" in line]
    assert lines, env.worker.log[-3000:]
    assert all("OpenCV uses 1 thread(s)" in line for line in lines), lines


def test_a_calibrated_camera_inline_and_exif_reach_the_tiled_scan(env):
    # A photo through a lens with barrel distortion, its camera given inline: the plan undistorts
    # it and every tile scans the undistorted photo; the same photo's EXIF alone gives the focal.
    realism = Realism(k1=-0.12, exif=CameraExif())
    shot = render_oblique_view(Box(120.0, 80.0, 60.0), style=Style(jpeg_quality=92), realism=realism, seed=3)
    h, w = shot.image.shape[:2]
    camera = {"fx": shot.focal_px, "fy": shot.focal_px, "cx": (w - 1) / 2, "cy": (h - 1) / 2,
              "dist": list(realism.distortion()), "image_width": w, "image_height": h}
    ref = env.upload(shot.jpeg, name="lens.jpg")
    clicks = [list(shot.points[n]) for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")]
    scale = {"kind": "edge", "edge": "width", "length_mm": 120.0}
    specs = [ScanSpec.model_validate({"image": ref, "points": clicks, "scale": scale, "camera": camera}),
             ScanSpec.model_validate({"image": ref, "points": clicks, "scale": scale})]
    job = env.wait(env.submit(specs), timeout=120)
    with_camera, with_exif = job.items
    assert with_camera.state == with_exif.state == State.succeeded, (with_camera.error, with_exif.error)
    assert with_camera.result.focal_source == "camera" and with_exif.result.focal_source == "exif"
    for item in job.items:
        dims = item.result.dimensions
        assert abs(dims["height"] / 80.0 - 1) < 0.02 and abs(dims["depth"] / 60.0 - 1) < 0.02, dims
        assert set(item.result.uncertainty) == {"width", "height", "depth"}
    # The service's result is the engine's own on the same input (tiles of the undistorted photo).
    local = run_scan(specs[0], load_image(shot.jpeg))
    assert with_camera.result.dimensions == report_dict(local.report)["dimensions"]


def test_bad_inputs_fail_only_their_items(env, scene):
    specs = [
        spec_for(env.upload(np.random.default_rng(7).bytes(5000), name="bad.png"), scene),
        spec_for(f"s3://not-readable/{uuid.uuid4().hex}.png", scene),
        spec_for(env.upload(encode(scene.image), tenant="globex"), scene),  # another tenant's
        spec_for(f"s3://{INPUTS_BUCKET}/missing.png", scene),
        spec_for(env.upload(encode(scene.image)), scene),
    ]
    job = env.wait(env.submit(specs))
    assert job.state == State.completed_with_failures and job.items_failed == 4, job
    states = [item.state for item in job.items]
    assert states == [State.failed] * 4 + [State.succeeded]
    errors = [item.error or "" for item in job.items]
    assert "'bad.png' is not a BMP, PNG, JPEG, TIFF or WebP image" in errors[0]
    assert "bucket 'not-readable' is not one the service may read" in errors[1]
    assert errors[2].startswith("no upload")
    assert "no object" in errors[3] and "missing.png" in errors[3]
    assert job.items[4].error is None and job.items[4].result.points > 0
    keys = env.keys(job.id)
    assert not any(k.startswith(("items/1/", "items/2/", "items/3/")) for k in keys), keys
    assert {k for k in keys if k.startswith("items/0/")} == {"items/0/front"}  # copied, then refused
    total, done = env.units(job.id)
    assert total == done == 4 * 2 + (2 * TILES_PER_FACE + 2)


def test_all_items_failing_fails_the_job(env, scene):
    job = env.wait(env.submit([spec_for(env.upload(b"\x89PNG but not really" * 50, "x.png"), scene)]))
    assert job.state == State.failed and job.error == "all items failed" and job.progress == 100
    assert "'x.png'" in job.items[0].error


def test_cancelled_before_it_runs_produces_nothing(env, scene):
    job_id = env.create([spec_for(env.upload(encode(scene.image)), scene)])
    assert env.store.transition(job_id, State.cancelled)
    before = env.runs(TASK_RUN_JOB), env.runs(TASK_PLAN_ITEM)
    env.celery.send_task(TASK_RUN_JOB, (job_id,))
    env.celery.send_task(TASK_PLAN_ITEM, (job_id, 0))  # as if sent just before the cancel
    deadline = time.monotonic() + 60
    while (env.runs(TASK_RUN_JOB), env.runs(TASK_PLAN_ITEM)) < (before[0] + 1, before[1] + 1):
        assert time.monotonic() < deadline, env.worker.log[-4000:]
        time.sleep(0.1)
    job = env.store.get(job_id)
    assert job.state == State.cancelled and job.items[0].state == State.cancelled  # never ran
    assert env.keys(job_id) == set()


def test_tasks_run_twice_write_each_object_once(env, scene):
    photo = encode(scene.image)
    spec = spec_for(env.upload(photo), scene)
    job_id = env.create([spec])
    # Start the job by hand and deliver its item twice, as a redelivery after a lost worker
    # would: two plans, two chords, every tile and the finish twice.
    assert env.store.transition(job_id, State.running) and env.store.next_item(job_id) == 0
    for _ in range(2):
        env.celery.send_task(TASK_PLAN_ITEM, (job_id, 0))
    job = env.wait(job_id)
    assert job.state == State.succeeded and job.progress == 100
    env.wait_no_task(job_id)  # the second copy's tiles and finish have run out (they find the job final)
    names = _tile_names(spec, load_image(photo))
    assert env.keys(job_id) == _item_files(0, names) | {"job.json"}
    total, done = env.units(job_id)
    assert total == done == 2 * TILES_PER_FACE + 2
    assert env.redis.scard(f"prism:job:{job_id}:tiles:0") == 2 * TILES_PER_FACE + 2
    local = run_scan(spec_for("x", scene), load_image(photo))
    assert job.items[0].result.points == report_dict(local.report)["points"]


def test_a_task_failing_for_good_fails_its_item_not_the_worker(env, scene):
    photo = encode(scene.image)
    spec = spec_for(env.upload(photo), scene)
    job_id = env.create([spec])
    assert env.store.transition(job_id, State.running) and env.store.next_item(job_id) == 0
    plan = plan_scan(spec, load_image(photo))
    env.objects.put_bytes(f"jobs/{job_id}/items/0/front", photo)
    env.objects.put_bytes(f"jobs/{job_id}/items/0/plan.json", dumps_plan(plan, tiles=[]))
    # A tile of a face the plan does not have: an error no retry can help (a bug, say).
    env.celery.send_task(TASK_SCAN_TILE, (job_id, 0, "top", 0, 1))
    job = env.wait(job_id)
    assert job.state == State.failed and job.error == "all items failed"
    assert job.items[0].state == State.failed
    assert job.items[0].error == "internal error: ValueError"


def _undone_tile(client, job_id: str, message: dict) -> bool:
    """Is this a scan_tile message whose tile is not finished yet? (A task acknowledges only
    after its work: one killed between the two is held unacknowledged with its tile done, and
    losing it loses nothing, so the watchdog never needs to step in.)"""
    if message["headers"]["task"] != TASK_SCAN_TILE:
        return False
    args = json.loads(base64.b64decode(message["body"]))[0]
    return not client.sismember(f"prism:job:{job_id}:tiles:{args[1]}", tile_id(*args[2:5]))


def _drop_one_message(client, job_id: str) -> str | None:
    """Delete one of the job's messages whose work is not done: a tile a worker held or else one
    queued; its task name.

    kombu's Redis transport can lose a message this way by itself: a worker killed between
    popping it from the queue and recording it as unacknowledged takes it along.
    """
    for tag, raw in client.hgetall(UNACKED_HASH).items():
        if job_id in raw and _undone_tile(client, job_id, json.loads(raw)[0]):
            client.hdel(UNACKED_HASH, tag)
            client.zrem(f"{UNACKED_HASH}_index", tag)
            return json.loads(raw)[0]["headers"]["task"]
    for name in queue_lists(QUEUE_SCANS):
        for raw in client.lrange(name, 0, -1):
            if job_id in raw:
                client.lrem(name, 1, raw)
                return json.loads(raw)["headers"]["task"]
    return None


def test_worker_killed_mid_job_finishes_it_without_duplicates(env, scene):
    """Last in the module: it kills and restarts the worker.

    The dead worker's messages come back after the visibility timeout, except one that the test
    deletes as lost: the watchdog finds the job stalled and restarts it where it stopped.
    """
    photo = encode(scene.image)
    specs = [spec_for(env.upload(photo), scene) for _ in range(4)]
    job_id = env.submit(specs)
    deadline = time.monotonic() + 60
    while env.store.get(job_id).progress <= 5:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    readies = env.worker.log.count(" ready.")
    env.worker.kill()  # SIGKILL to the group: tasks in flight die unacknowledged
    lost = _drop_one_message(env.redis, job_id)
    assert lost is not None, "the job had no message left to lose"
    env.worker.start()
    deadline = time.monotonic() + 60
    while env.worker.log.count(" ready.") == readies:
        assert time.monotonic() < deadline, env.worker.log[-4000:]
        time.sleep(0.1)
    job = env.wait(job_id, timeout=180)  # the visibility timeout, a stall and a sweep, then the rest
    assert job.state == State.succeeded, (lost, job)
    assert f"watchdog: job {job_id} made no progress" in env.worker.log, lost
    assert all(item.state == State.succeeded for item in job.items), job
    local = run_scan(specs[0], load_image(photo))
    assert {item.result.points for item in job.items} == {report_dict(local.report)["points"]}
    names = _tile_names(specs[0], load_image(photo))
    assert env.keys(job_id) == set().union(*(_item_files(i, names) for i in range(4))) | {"job.json"}
    total, done = env.units(job_id)
    assert total == done == 4 * (2 * TILES_PER_FACE + 2)

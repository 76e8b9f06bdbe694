"""Batch items scanned whole in one task (no tiles): the same outputs as the engine's own, and
nothing stored on the way; a bad item beside them fails alone; a redelivered task adds nothing.

The worker here keeps 2 tiles per face and 2 items in flight per job, so a lone photo is still
split into tiles while every item of a batch (one tile per face) is scanned whole.
"""

from __future__ import annotations

import io
from collections.abc import Iterator

import pytest
from prism_common.queue import TASK_PLAN_ITEM
from prism_common.records import State

from prismcore import run_scan
from prismcore.io.images import load_image
from prismcore.outputs.writers import write_csv, write_ply
from prismcore.report import report_dict
from prismcore.scan.cloud import PREVIEW_POINTS, Cloud, decimate
from prismsynth import Box, render_oblique_view

from .worker_env import Env, encode, spec_for, worker_env

OUTPUTS = {"cloud.csv", "cloud.ply", "preview.ply", "overlay.jpg", "report.json"}


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=4,
                    bucket="t-whole", tiles_per_face=2, items_in_flight=2) as made:
        yield made


@pytest.fixture(scope="module")
def scenes():
    return [render_oblique_view(Box(120.0, 80.0, 60.0), seed=1),
            render_oblique_view(Box(90.0, 140.0, 45.0), seed=4)]


def _expected_files(cloud: Cloud) -> dict[str, bytes]:
    csv, ply, preview = io.BytesIO(), io.BytesIO(), io.BytesIO()
    write_csv(csv, cloud.points)
    write_ply(ply, cloud.points, cloud.colors)
    small = decimate(cloud)
    assert len(small.points) == min(len(cloud.points), PREVIEW_POINTS)
    write_ply(preview, small.points, small.colors)
    return {"cloud.csv": csv.getvalue(), "cloud.ply": ply.getvalue(), "preview.ply": preview.getvalue()}


def test_batch_items_are_scanned_whole_and_match_the_engine(env, scenes):
    photos = [encode(s.image) for s in scenes]
    specs = [spec_for(env.upload(photos[0]), scenes[0]),
             spec_for(env.upload(b"GIF89a not a photo", name="bad.gif"), scenes[0]),
             spec_for(env.upload(photos[1]), scenes[1])]
    job = env.wait(env.submit(specs))
    assert job.state == State.completed_with_failures and job.progress == 100, job
    assert (job.items_failed, job.error) == (1, "1 of 3 items failed")
    assert [item.state for item in job.items] == [State.succeeded, State.failed, State.succeeded]
    assert job.items[1].error == "'bad.gif' is a GIF image; supported formats are BMP, PNG, JPEG, TIFF, WebP"
    total, done = env.units(job.id)
    assert total == done == 3 * 2  # plan + complete per item, no tiles
    # Only the outputs: no copied inputs, plan.json or tiles on the way.
    assert env.keys(job.id) == {f"items/{i}/{name}" for i in (0, 2) for name in OUTPUTS} | {"job.json"}
    for index, photo, spec in ((0, photos[0], specs[0]), (2, photos[1], specs[2])):
        local = run_scan(spec, load_image(photo))
        item = job.items[index]
        assert item.result.points == report_dict(local.report)["points"]
        assert item.result.dimensions == report_dict(local.report)["dimensions"]
        expected = _expected_files(local.cloud)
        for kind, name in (("csv", "cloud.csv"), ("ply", "cloud.ply"), ("preview", "preview.ply")):
            assert env.objects.get_bytes(item.outputs[kind]) == expected[name], (index, name)


def test_a_redelivered_batch_item_writes_each_object_once(env, scenes):
    photo = encode(scenes[0].image)
    specs = [spec_for(env.upload(photo), scenes[0]) for _ in range(2)]
    job_id = env.create(specs)
    assert env.store.transition(job_id, State.running) and env.store.next_item(job_id) == 0
    for _ in range(2):  # item 0 twice, as after a lost worker; it starts item 1 itself
        env.celery.send_task(TASK_PLAN_ITEM, (job_id, 0))
    job = env.wait(job_id)
    assert job.state == State.succeeded and [i.state for i in job.items] == [State.succeeded] * 2
    env.wait_no_task(job_id)  # the second copy has run out
    assert env.keys(job_id) == {f"items/{i}/{name}" for i in (0, 1) for name in OUTPUTS} | {"job.json"}
    total, done = env.units(job_id)
    assert total == done == 2 * 2
    assert job.items[0].result == job.items[1].result

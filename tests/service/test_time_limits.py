"""Every task has a soft and a hard time limit; a task that hits one fails its item with the
reason, and the worker goes on with other work (a real worker with a 2 s limit)."""

from __future__ import annotations

import inspect
import re
from collections.abc import Iterator

import numpy as np
import pytest
from prism_common import queue
from prism_common.queue import (
    TASK_DELIVER_WEBHOOK,
    TASK_EXTRACT_FRAME,
    TASK_FIND_POINTS,
    TASK_FINISH_ITEM,
    TASK_PLAN_ITEM,
    TASK_RUN_JOB,
    TASK_SCAN_FRAME,
    TASK_SCAN_TILE,
    TASK_SPLIT_VIDEO,
    make_celery,
    time_limits,
)
from prism_common.records import State
from prism_common.settings import Settings

import prism_worker.tasks
from prismsynth import Box, render_oblique_view

from .conftest import API_KEYS, WEBHOOK_SECRET
from .worker_env import Env, encode, spec_for, worker_env

# 1 s was a knife edge for the small photo below: its task (the scan, then its outputs stored)
# took 0.68 s with a CI run and CPU burners beside it (load 8, 2 cores). The large photo needs
# 4.6 s of CPU before its outputs are stored: still 2x past 2 s on an idle machine.
LIMIT_S = 2
ALL_TASKS = (TASK_RUN_JOB, TASK_PLAN_ITEM, TASK_SCAN_TILE, TASK_FINISH_ITEM, TASK_SCAN_FRAME,
             TASK_SPLIT_VIDEO, TASK_DELIVER_WEBHOOK, TASK_EXTRACT_FRAME, TASK_FIND_POINTS)


def test_every_task_has_a_soft_limit_below_its_hard_limit():
    settings = Settings(api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET, task_time_limit_s=100,
                        task_hard_margin_s=20)
    limits = time_limits(settings)
    assert set(limits) == set(ALL_TASKS)
    # Every task the worker defines has its limits (read from its source: the app's registry
    # would need the worker's settings).
    registered = re.findall(r"@app\.task\(name=(TASK_\w+)", inspect.getsource(prism_worker.tasks))
    assert {getattr(queue, name) for name in registered} == set(ALL_TASKS)
    for name, limit in limits.items():
        assert 0 < limit["soft_time_limit"] < limit["time_limit"], name
    assert limits[TASK_SCAN_TILE] == {"soft_time_limit": 100, "time_limit": 120}
    # The worker's app carries them (Celery applies annotations to the registered tasks).
    assert make_celery(settings).conf.task_annotations == limits


@pytest.fixture(scope="module")
def env(redis_server, s3_server, tmp_path_factory) -> Iterator[Env]:
    with worker_env(redis_server, s3_server, tmp_path_factory.mktemp("worker"), db=11,
                    bucket="t-limits", tiles_per_face=1, items_in_flight=2,
                    extra_env={"TASK_TIME_LIMIT_S": str(LIMIT_S), "TASK_HARD_MARGIN_S": "5"}) as made:
        yield made


def test_an_item_over_the_time_limit_fails_with_the_reason_and_the_next_one_runs(env):
    small = render_oblique_view(Box(120.0, 80.0, 60.0), seed=1)
    # A photo 4x the size each way, points scaled with it: ~20 M pixels, a whole-item scan
    # with its cloud written out takes several seconds on any machine, well past the limit
    # (decode 0.2, scan 1.9, its 10 M-point LAZ 2.4 s of CPU).
    big = np.kron(small.image, np.ones((4, 4, 1), dtype=np.uint8))
    big_points = [[4 * c + 1.5 for c in small.points[n]] for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")]
    spec_big = spec_for(env.upload(encode(big, ".jpg"), "big.jpg"), small).model_copy(
        update={"points": spec_for("x", small).points.model_validate(big_points),
                "focal_px": 4 * small.focal_px})
    job_id = env.submit([spec_big])
    job = env.wait(job_id, timeout=120)
    assert job.state == State.failed or job.items[0].state == State.failed, job
    error = job.items[0].error or ""
    assert f"time limit of {LIMIT_S} s" in error, error
    # The worker is not held: a small photo right after succeeds, well inside the limit on a
    # loaded machine too (its task took 0.68 s at a load of 8 on 2 cores). The limit is the wall
    # clock's, so a stall of the whole machine past it may fail that one try: another is made
    # then (never for any other error), and one of three must succeed.
    tiny = render_oblique_view(Box(120.0, 80.0, 60.0), image_size=(320, 256), focal_px=350.0, seed=1)
    ref = env.upload(encode(tiny.image))
    for _ in range(3):
        ok = env.wait(env.submit([spec_for(ref, tiny)]), timeout=60)
        if f"time limit of {LIMIT_S} s" not in (ok.items[0].error or ""):
            break
    assert ok.items[0].state == State.succeeded, ok.items[0].error

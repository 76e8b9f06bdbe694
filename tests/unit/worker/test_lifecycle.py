"""The job and item transitions (prism_worker.lifecycle) on in-memory fakes."""

from __future__ import annotations

import json
import random

import pytest
from billiard.exceptions import SoftTimeLimitExceeded
from botocore.exceptions import ClientError, EndpointConnectionError
from prism_common.queue import TASK_DELIVER_WEBHOOK, TASK_PLAN_ITEM
from prism_common.records import ItemResult, State
from prism_common.store import UNITS_PER_ITEM_ESTIMATE
from redis import ConnectionError as RedisConnectionError

from prism_worker import lifecycle

from .conftest import Fakes

RESULT = ItemResult(points=10, dimensions={"width": 1.0, "height": 2.0, "depth": 3.0, "unit": "mm"},
                    point_loss=0.0, warnings=[])


def _plans_sent(fakes: Fakes) -> list[int]:
    return [args[1] for name, args in fakes.sent.take() if name == TASK_PLAN_ITEM]


def _succeed(fakes: Fakes, job_id: str, item: int) -> None:
    view = fakes.store.get_item(job_id, item)
    assert view is not None
    lifecycle.count_plan(fakes.ctx, job_id, item, 0)
    lifecycle.succeed_item(fakes.ctx, job_id, view.item, RESULT, {"csv": f"jobs/{job_id}/{item}.csv"})


def _run(fakes: Fakes, job_id: str, outcomes: list[bool]) -> list[int]:
    """Run the job as the tasks would: each plan_item sent gives its item the outcome in
    `outcomes` (True: succeeded) and completes it. Returns the items in the order they started."""
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    started: list[int] = []
    while queue := _plans_sent(fakes):
        for item in queue:
            started.append(item)
            if outcomes[item]:
                _succeed(fakes, job_id, item)
            else:
                lifecycle.fail_item(fakes.ctx, job_id, item, f"bad photo {item}")
            lifecycle.complete_item(fakes.ctx, job_id, item, maybe_repeat=False)
    return started


@pytest.mark.parametrize("n_items", [1, 2, 5])
@pytest.mark.parametrize("window", [1, 2, 4])
def test_start_job_starts_one_window_of_items(fakes: Fakes, n_items: int, window: int) -> None:
    fakes = fakes.with_settings(items_in_flight_per_job=window)
    job_id = fakes.job(items=n_items)
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    assert fakes.store.state(job_id) == State.running
    assert _plans_sent(fakes) == list(range(min(window, n_items)))


def test_a_second_delivery_of_run_job_starts_nothing_unless_it_may_be_a_repeat(fakes: Fakes) -> None:
    job_id = fakes.job(items=5)
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    assert _plans_sent(fakes) == [0, 1]
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    assert _plans_sent(fakes) == []
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=True)  # a retry: refills, new indices only
    assert _plans_sent(fakes) == [2, 3]


@pytest.mark.parametrize("state", [State.succeeded, State.completed_with_failures, State.failed,
                                   State.cancelled])
def test_an_ended_job_is_not_started(fakes: Fakes, state: State) -> None:
    job_id = fakes.job(items=2, state=state)
    for repeat in (False, True):
        lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=repeat)
    assert fakes.store.state(job_id) == state and fakes.sent.sent == []


@pytest.mark.parametrize("outcomes", [[True], [False], [True, False, True], [False, False, False],
                                      [False] * 6 + [True], [True] * 7])
@pytest.mark.parametrize("window", [1, 3])
def test_a_job_runs_every_item_once_and_ends_as_its_items_say(fakes: Fakes, outcomes: list[bool],
                                                              window: int) -> None:
    fakes = fakes.with_settings(items_in_flight_per_job=window)
    job_id = fakes.job(items=len(outcomes))
    assert sorted(_run(fakes, job_id, outcomes)) == list(range(len(outcomes)))
    job = fakes.store.get(job_id)
    assert job is not None
    # Succeeded only when every item did; some failed of several: completed_with_failures.
    failed = outcomes.count(False)
    if not failed:
        assert (job.state, job.error) == (State.succeeded, None)
    elif failed == len(outcomes):
        assert (job.state, job.error) == (State.failed, "all items failed")
    else:
        assert (job.state, job.error) == (State.completed_with_failures,
                                          f"{failed} of {len(outcomes)} items failed")
    assert [i.state for i in job.items] == [State.succeeded if ok else State.failed for ok in outcomes]
    assert job.items_done == len(outcomes) and job.items_failed == failed and job.progress == 100
    # Every unit counted: plan + complete per item, tiles 0 (the estimate replaced once).
    raw = fakes.redis.hgetall(f"prism:job:{job_id}")
    assert int(raw["units_total"]) == int(raw["units_done"]) == 2 * len(outcomes)
    saved = json.loads(fakes.objects.get_bytes(f"jobs/{job_id}/job.json"))
    assert saved["state"] == job.state.value and len(saved["items"]) == len(outcomes)


@pytest.mark.parametrize("webhook_url", [None, "https://hooks.example.com/prism"])
def test_the_webhook_is_sent_once_when_a_job_with_one_ends(fakes: Fakes, webhook_url: str | None) -> None:
    job_id = fakes.job(items=2, webhook_url=webhook_url)
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    fakes.sent.take()
    for item in (0, 1):
        _succeed(fakes, job_id, item)
        lifecycle.complete_item(fakes.ctx, job_id, item, maybe_repeat=False)
    lifecycle.complete_item(fakes.ctx, job_id, 1, maybe_repeat=False)  # a second delivery
    hooks = [args for name, args in fakes.sent.take() if name == TASK_DELIVER_WEBHOOK]
    assert hooks == ([(job_id,)] if webhook_url else [])


def test_completing_an_item_twice_starts_one_next_item_unless_it_may_be_a_repeat(fakes: Fakes) -> None:
    fakes = fakes.with_settings(items_in_flight_per_job=1)
    job_id = fakes.job(items=4)
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    assert _plans_sent(fakes) == [0]
    _succeed(fakes, job_id, 0)
    lifecycle.complete_item(fakes.ctx, job_id, 0, maybe_repeat=False)
    lifecycle.complete_item(fakes.ctx, job_id, 0, maybe_repeat=False)
    assert _plans_sent(fakes) == [1]
    lifecycle.complete_item(fakes.ctx, job_id, 0, maybe_repeat=True)  # one too many is harmless
    assert _plans_sent(fakes) == [2]
    assert fakes.store.get(job_id).items_done == 1  # counted once


def test_a_cancelled_job_starts_no_more_items(fakes: Fakes) -> None:
    job_id = fakes.job(items=3)
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    fakes.sent.take()
    fakes.store.transition(job_id, State.cancelled)
    lifecycle.fail_and_complete(fakes.ctx, job_id, 0, "late", maybe_repeat=True)
    assert fakes.sent.sent == [] and fakes.store.state(job_id) == State.cancelled
    assert not fakes.objects.exists(f"jobs/{job_id}/job.json")


def test_a_cancelled_jobs_progress_is_what_had_finished_at_the_cancel(fakes: Fakes) -> None:
    job_id = fakes.job(items=4, state=State.running)
    _succeed(fakes, job_id, 0)
    at_cancel = fakes.store.get(job_id).progress
    fakes.store.transition(job_id, State.cancelled)
    # Tasks in flight at the cancel count their units on the way out (a whole item's plan).
    lifecycle.count_plan(fakes.ctx, job_id, 1, 0)
    fakes.store.tile_done(job_id, 2, "front-0-10")
    assert 0 < at_cancel < 100 and fakes.store.get(job_id).progress == at_cancel
    assert [i.state for i in fakes.store.get(job_id).items] == [State.succeeded] + [State.cancelled] * 3


def _finish_items(fakes: Fakes, job_id: str, count: int, tiles: int = 0) -> None:
    """Run the job as the worker does until `count` items are done: an item scanned whole
    counts its plan when its scan is done (tiles=0); a tiled one is planned, then each tile
    counts. The window's next items are left started (sent), not yet planned."""
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    waiting = _plans_sent(fakes)
    for _ in range(count):
        item = waiting.pop(0)
        view = fakes.store.get_item(job_id, item)
        assert view is not None
        lifecycle.count_plan(fakes.ctx, job_id, item, tiles)
        for tile in range(tiles):
            fakes.store.tile_done(job_id, item, f"front-{tile}")
        lifecycle.succeed_item(fakes.ctx, job_id, view.item, RESULT, {})
        lifecycle.complete_item(fakes.ctx, job_id, item, maybe_repeat=False)
        waiting += _plans_sent(fakes)


@pytest.mark.parametrize("tiles", [0, 4])
@pytest.mark.parametrize(("done", "n_items", "expected"), [(4, 40, 10), (10, 12, 83), (0, 5, 0),
                                                           (1, 3, 33)])
def test_progress_is_finished_work_over_all_work(fakes: Fakes, done: int, n_items: int, expected: int,
                                                 tiles: int) -> None:
    # Items still to be planned are as big as the planned ones: 4 of 40 batch items (2 units
    # each, scanned whole) read 2 % and 10 of 12 read 50 % while they were taken to be 10 units.
    job_id = fakes.job(items=n_items)
    _finish_items(fakes, job_id, done, tiles=tiles)
    job = fakes.store.get(job_id)
    assert job is not None and job.items_done == done and job.state == State.running
    assert job.progress == expected


def test_progress_counts_an_item_in_flight_by_its_finished_tiles(fakes: Fakes) -> None:
    job_id = fakes.job(items=4)
    _finish_items(fakes, job_id, 1, tiles=8)  # 10 units of 40
    lifecycle.count_plan(fakes.ctx, job_id, 1, 8)
    for tile in range(4):  # half of the next item's tiles
        fakes.store.tile_done(job_id, 1, f"front-{tile}")
    assert fakes.store.get(job_id).progress == 100 * (10 + 1 + 4) // 40


def test_a_cancelled_batch_keeps_the_progress_of_its_finished_items(fakes: Fakes) -> None:
    job_id = fakes.job(items=40)
    _finish_items(fakes, job_id, 4)
    fakes.store.transition(job_id, State.cancelled)
    lifecycle.count_plan(fakes.ctx, job_id, 4, 0)  # a whole scan in flight counts on its way out
    assert fakes.store.get(job_id).progress == 10


def test_a_failure_keeps_the_first_outcome(fakes: Fakes) -> None:
    job_id = fakes.job(items=2, state=State.running)
    lifecycle.fail_item(fakes.ctx, job_id, 0, "first")
    lifecycle.fail_item(fakes.ctx, job_id, 0, "second")
    _succeed(fakes, job_id, 1)
    lifecycle.fail_item(fakes.ctx, job_id, 1, "after success")
    job = fakes.store.get(job_id)
    assert (job.items[0].state, job.items[0].error) == (State.failed, "first")
    assert (job.items[1].state, job.items[1].error) == (State.succeeded, None)


def test_failing_an_item_of_no_job_writes_nothing(fakes: Fakes) -> None:
    lifecycle.fail_and_complete(fakes.ctx, "f" * 32, 0, "gone", maybe_repeat=True, tile="front-0-10")
    assert fakes.redis.keys("*") == [] and fakes.sent.sent == []


@pytest.mark.parametrize("tiles", [0, 1, 4, 16])
def test_the_plan_replaces_the_estimate_once(fakes: Fakes, tiles: int) -> None:
    job_id = fakes.job(items=3, state=State.running)
    total = lambda: int(fakes.redis.hget(f"prism:job:{job_id}", "units_total"))  # noqa: E731
    assert total() == 3 * UNITS_PER_ITEM_ESTIMATE
    for _ in range(2):
        lifecycle.count_plan(fakes.ctx, job_id, 1, tiles)
    assert total() == 2 * UNITS_PER_ITEM_ESTIMATE + tiles + 2


def test_a_failed_tile_counts_as_done(fakes: Fakes) -> None:
    job_id = fakes.job(items=1, state=State.running)
    lifecycle.count_plan(fakes.ctx, job_id, 0, 2)
    lifecycle.fail_item(fakes.ctx, job_id, 0, "tile died", tile="front-0-10")
    assert int(fakes.redis.hget(f"prism:job:{job_id}", "units_done")) == 2  # plan + that tile


@pytest.mark.parametrize("repeat", [False, True])
def test_only_a_first_run_marks_an_item_running(fakes: Fakes, repeat: bool) -> None:
    job_id = fakes.job(items=1, state=State.running)
    view = lifecycle.open_item(fakes.ctx, job_id, 0, repeat=repeat)
    assert view is not None
    lifecycle.mark_running(fakes.ctx, view, repeat=repeat)
    assert fakes.store.get(job_id).items[0].state == (State.queued if repeat else State.running)


@pytest.mark.parametrize(("job_state", "item_done", "is_open"), [
    (State.running, False, True), (State.running, True, False), (State.queued, False, False),
    (State.cancelled, False, False), (State.succeeded, True, False)])
def test_open_item(fakes: Fakes, job_state: State, item_done: bool, is_open: bool) -> None:
    job_id = fakes.job(items=1, state=State.running)
    if item_done:
        _succeed(fakes, job_id, 0)
    if job_state == State.queued:
        job_id = fakes.job(items=1)
    elif job_state != State.running:
        fakes.store.transition(job_id, job_state)
    assert (lifecycle.open_item(fakes.ctx, job_id, 0, repeat=False) is not None) == is_open


def test_a_repeat_about_an_ended_job_writes_its_document_again(fakes: Fakes) -> None:
    job_id = fakes.job(items=1)
    _run(fakes, job_id, [True])
    fakes.objects.delete_keys([f"jobs/{job_id}/job.json"])  # the run that ended it died here
    assert lifecycle.open_item(fakes.ctx, job_id, 0, repeat=False) is None
    assert not fakes.objects.exists(f"jobs/{job_id}/job.json")
    assert lifecycle.open_item(fakes.ctx, job_id, 0, repeat=True) is None
    assert json.loads(fakes.objects.get_bytes(f"jobs/{job_id}/job.json"))["state"] == "succeeded"


def test_items_completed_in_any_order_end_the_job_once(fakes: Fakes) -> None:
    fakes = fakes.with_settings(items_in_flight_per_job=8)
    job_id = fakes.job(items=8, webhook_url="https://hooks.example.com/h")
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    order = _plans_sent(fakes)
    random.Random(3).shuffle(order)
    for item in order:
        _succeed(fakes, job_id, item)
    for item in order + order[:3]:  # and three redeliveries
        lifecycle.complete_item(fakes.ctx, job_id, item, maybe_repeat=False)
    assert fakes.sent.names() == [TASK_DELIVER_WEBHOOK]
    assert fakes.store.get(job_id).state == State.succeeded


@pytest.mark.parametrize(("exc", "retries", "expected"), [
    (EndpointConnectionError(endpoint_url="http://s3.internal:8333"), 5,
     "the object store was unreachable (gave up after 5 retries)"),
    (ClientError({"Error": {"Code": "SlowDown"}}, "PutObject"), 0,
     "the object store refused a request (SlowDown)"),
    (RedisConnectionError("redis.internal:6379 refused"), 2,
     "the job store (Redis) was unreachable (gave up after 2 retries)"),
    (KeyError("secret-bucket/key"), 0, "internal error: KeyError"),
])
def test_failure_reasons_name_the_backend_not_its_address(exc: BaseException, retries: int,
                                                          expected: str) -> None:
    assert lifecycle.failure_reason(exc, retries) == expected


def test_a_time_limit_reason_names_the_limit() -> None:
    reason = lifecycle.failure_reason(SoftTimeLimitExceeded(), 0, 300.0)
    assert reason.startswith("took longer than the worker's time limit of 300 s")
    assert "PRISM_TASK_TIME_LIMIT_S" in reason


@pytest.mark.parametrize("tiles", [0, 4])
def test_a_plan_counts_its_unit_and_the_item_size_in_one_write_once(fakes: Fakes, tiles: int) -> None:
    # Two writes once: a connection lost between them left the total at the estimate for good
    # (a cluster job that succeeded read units 4 of 12). Run twice, as a redelivered task does.
    job_id = fakes.job(items=2)
    for _ in range(2):
        lifecycle.count_plan(fakes.ctx, job_id, 0, tiles)
    units = fakes.redis.hmget(f"prism:job:{job_id}", "units_total", "units_done", "items_planned")
    # Item 1 is still counted at its estimate.
    assert [int(v) for v in units] == [UNITS_PER_ITEM_ESTIMATE + tiles + 2, 1, 1]

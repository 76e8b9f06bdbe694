"""The watchdog's sweep, the restarts and failures it decides (prism_worker.lifecycle), and
retention, on in-memory fakes with a clock the test moves."""

from __future__ import annotations

import json

import pytest
from prism_common.queue import TASK_DELIVER_WEBHOOK, TASK_FINISH_ITEM, TASK_PLAN_ITEM, TASK_RUN_JOB
from prism_common.records import State
from prism_common.upload_keys import frame_png_key, points_key, upload_key, video_info_key

from prism_worker import lifecycle, watchdog

from .conftest import Fakes

STALL = 100  # conftest's job_stall_timeout_s
MAX_AGE = 10_000


def _message(job_id: str, *args: object) -> str:
    """A broker message as Celery writes it (only the part the watchdog reads matters)."""
    argsrepr = repr((job_id, *args))
    return json.dumps({"body": "...", "headers": {"task": "prism.plan_item", "argsrepr": argsrepr}})


def _sweep_at(fakes: Fakes, offset: float) -> dict[str, int]:
    return watchdog.sweep(fakes.ctx, fakes.clock.now + offset)


def _claim(fakes: Fakes, job_id: str, count: int) -> None:
    for _ in range(count):
        fakes.store.next_item(job_id)


@pytest.mark.parametrize("state", [State.queued, State.running])
def test_a_job_that_moves_is_never_restarted(fakes: Fakes, state: State) -> None:
    job_id = fakes.job(items=2, state=state)
    for step in range(6):
        if step:
            fakes.store.add_units(job_id, done=1)
        assert _sweep_at(fakes, step * (STALL - 1)) == {"jobs": 1, "restarted": 0, "failed": 0}
    assert fakes.sent.sent == []


@pytest.mark.parametrize("where", ["scans", "scans\x06\x163", "unacked", "webhooks"])
def test_a_job_with_a_task_in_the_broker_is_waiting_its_turn(fakes: Fakes, where: str) -> None:
    job_id = fakes.job(items=1, state=State.running)
    if where == "unacked":
        fakes.redis.hset("unacked", "tag-1", json.dumps([json.loads(_message(job_id, 0)), "", "scans"]))
    else:
        fakes.redis.lpush(where, _message(job_id, 0))
    for t in (0, STALL + 1, 3 * STALL, 10 * STALL):
        assert _sweep_at(fakes, t)["restarted"] == 0
    assert fakes.sent.sent == [] and fakes.store.state(job_id) == State.running


def test_another_jobs_task_does_not_keep_a_job_waiting(fakes: Fakes) -> None:
    job_id, other = fakes.job(items=1), fakes.job(items=1)
    fakes.redis.lpush("scans", _message(other))
    _sweep_at(fakes, 0)
    assert _sweep_at(fakes, STALL + 1)["restarted"] == 1  # `other` is waiting, `job_id` is not
    assert fakes.sent.sent == [(TASK_RUN_JOB, (job_id,))]


@pytest.mark.parametrize(("claimed", "decided", "done", "expected"), [
    (2, [], [], [(TASK_PLAN_ITEM, 0), (TASK_PLAN_ITEM, 1)]),
    (2, [1], [], [(TASK_PLAN_ITEM, 0), (TASK_FINISH_ITEM, 1)]),
    (2, [0], [0], [(TASK_PLAN_ITEM, 1)]),
    (3, [0, 1], [0, 1], [(TASK_PLAN_ITEM, 2)]),
    (1, [0], [0], [(TASK_PLAN_ITEM, 1), (TASK_PLAN_ITEM, 2)]),  # the window was lost: refilled
])
def test_a_restart_resends_what_the_job_waits_for(fakes: Fakes, claimed: int, decided: list[int],
                                                    done: list[int], expected: list[tuple[str, int]]) -> None:
    job_id = fakes.job(items=4, state=State.running)
    _claim(fakes, job_id, claimed)
    for i in decided:
        view = fakes.store.get_item(job_id, i)
        fakes.store.put_item(job_id, view.item.model_copy(update={"state": State.succeeded}))
    for i in done:
        fakes.store.item_done(job_id, i)
    lifecycle.restart_job(fakes.ctx, fakes.store.get(job_id))
    sent = [(name, args[-1] if name == TASK_FINISH_ITEM else args[1]) for name, args in fakes.sent.sent]
    assert sorted(sent) == sorted(expected)


def test_a_restart_of_a_job_whose_last_completion_was_lost_ends_it(fakes: Fakes) -> None:
    job_id = fakes.job(items=2, state=State.running)
    _claim(fakes, job_id, 2)
    for i in (0, 1):
        view = fakes.store.get_item(job_id, i)
        fakes.store.put_item(job_id, view.item.model_copy(update={"state": State.failed, "error": "x"}))
        fakes.store.item_done(job_id, i)
    assert lifecycle.restart_job(fakes.ctx, fakes.store.get(job_id)) == "job ended"
    assert fakes.store.state(job_id) == State.failed


def test_a_queued_job_whose_message_was_lost_is_sent_again(fakes: Fakes) -> None:
    job_id = fakes.job(items=1)
    _sweep_at(fakes, 0)
    assert _sweep_at(fakes, STALL - 1)["restarted"] == 0
    assert _sweep_at(fakes, STALL + 1)["restarted"] == 1
    assert fakes.sent.sent == [(TASK_RUN_JOB, (job_id,))]


@pytest.mark.parametrize("restarts", [0, 1, 3])
def test_a_job_that_stays_stalled_fails_after_its_restarts(fakes: Fakes, restarts: int) -> None:
    fakes = fakes.with_settings(job_stall_restarts=restarts)
    job_id = fakes.job(items=3, state=State.running, webhook_url="https://hooks.example.com/h")
    _claim(fakes, job_id, 2)
    view = fakes.store.get_item(job_id, 1)
    fakes.store.put_item(job_id, view.item.model_copy(update={"state": State.succeeded}))
    _sweep_at(fakes, 0)
    for k in range(1, restarts + 1):
        counts = _sweep_at(fakes, k * (STALL + 1))
        assert counts["restarted"] == 1 and counts["failed"] == 0
    assert _sweep_at(fakes, (restarts + 1) * (STALL + 1))["failed"] == 1
    job = fakes.store.get(job_id)
    reason = f"stalled: no progress for {STALL} s, {restarts} restarts did not help"
    assert (job.state, job.error) == (State.failed, reason)
    assert [i.state for i in job.items] == [State.failed, State.succeeded, State.failed]
    assert json.loads(fakes.objects.get_bytes(f"jobs/{job_id}/job.json"))["error"] == reason
    assert fakes.sent.names()[-1] == "prism.deliver_webhook"


def test_progress_forgives_earlier_restarts(fakes: Fakes) -> None:
    job_id = fakes.job(items=1, state=State.running)
    _claim(fakes, job_id, 1)
    _sweep_at(fakes, 0)
    assert _sweep_at(fakes, STALL + 1)["restarted"] == 1  # its one restart
    fakes.store.add_units(job_id, done=1)
    _sweep_at(fakes, 2 * STALL)
    assert _sweep_at(fakes, 3 * STALL + 1)["restarted"] == 1  # a fresh restart, not a failure
    assert fakes.store.state(job_id) == State.running


@pytest.mark.parametrize(("age", "fails"), [(MAX_AGE - 60, False), (MAX_AGE + 5, True)])
def test_jobs_past_the_maximum_age_fail_whatever_else(fakes: Fakes, age: float, fails: bool) -> None:
    fakes = fakes.with_settings(job_max_age_s=MAX_AGE)
    job_id = fakes.job(items=1, state=State.running, age_s=age)
    fakes.redis.lpush("scans", _message(job_id, 0))  # busy, still
    assert _sweep_at(fakes, 0)["failed"] == int(fails)
    job = fakes.store.get(job_id)
    assert job.state == (State.failed if fails else State.running)
    if fails:
        assert job.error == f"not finished {MAX_AGE} s after it was submitted"


def test_an_ended_job_is_not_failed_again(fakes: Fakes) -> None:
    job_id = fakes.job(items=1, state=State.succeeded)
    assert lifecycle.fail_job(fakes.ctx, fakes.store.get(job_id), "late") is False
    assert fakes.store.state(job_id) == State.succeeded and fakes.sent.sent == []


def test_one_sweep_per_interval_on_the_contexts_clock(fakes: Fakes) -> None:
    job_id = fakes.job(items=1)
    assert watchdog.try_sweep(fakes.ctx, "worker-a") is not None
    assert watchdog.try_sweep(fakes.ctx, "worker-b") is None  # a's lock holds for the interval
    assert fakes.store.get_watch(job_id)["since"] == str(fakes.clock.now)
    fakes.redis.delete("prism:watchdog:lock")  # the interval passed
    fakes.clock.advance(STALL + 1)
    assert watchdog.try_sweep(fakes.ctx, "worker-b")["restarted"] == 1


def test_uploads_past_their_ttl_go_with_their_frames(fakes: Fakes) -> None:
    ttl = fakes.ctx.settings.upload_ttl_s
    ids = {"old": "a" * 32, "new": "b" * 32}
    for upload_id in ids.values():
        key = upload_key("acme", upload_id)
        fakes.store.put_upload(upload_id, tenant="acme", key=key, size=3, name="clip.avi")
        for k in (key, video_info_key("acme", upload_id), frame_png_key("acme", upload_id, 7),
                  points_key("acme", upload_id, None, (3, 4))):
            fakes.objects.put_bytes(k, b"abc")
    fakes.objects.put_bytes("jobs/" + "c" * 32 + "/items/0/cloud.csv", b"1,2,3\n")
    now = fakes.clock.now
    fakes.redis.zadd("prism:uploads", {ids["old"]: now - ttl - 5})
    fakes.redis.zadd("prism:uploads", {ids["new"]: now})
    assert watchdog.expire_uploads(fakes.ctx, now) == 1
    assert not any(ids["old"] in k for k in fakes.objects.objects)
    assert sum(ids["new"] in k for k in fakes.objects.objects) == 4
    assert fakes.store.get_upload(ids["old"]) is None and fakes.store.get_upload(ids["new"]) is not None
    assert watchdog.expire_uploads(fakes.ctx, now) == 0


@pytest.mark.parametrize(("job_ttl_days", "expired"), [(0, 0), (30, 1), (40, 0)])
def test_ended_jobs_past_their_ttl_go(fakes: Fakes, job_ttl_days: int, expired: int) -> None:
    day = 86_400
    fakes = fakes.with_settings(job_ttl_s=job_ttl_days * day, job_max_age_s=day)
    old_done = fakes.job(items=2, state=State.succeeded, age_s=31 * day)
    old_running = fakes.job(items=1, state=State.running, age_s=31 * day)
    for job_id in (old_done, old_running):
        fakes.objects.put_bytes(f"jobs/{job_id}/job.json", b"{}")
    fakes.store.tile_done(old_done, 0, "front-0-10")
    assert watchdog.expire_jobs(fakes.ctx, fakes.clock.now) == expired
    assert (fakes.store.get(old_done) is None) == bool(expired)
    assert fakes.objects.exists(f"jobs/{old_done}/job.json") != bool(expired)
    assert fakes.store.get(old_running) is not None  # a running job is never deleted
    if expired:
        assert not [k for k in fakes.redis.keys("*") if old_done in k]


def _ended_with_a_webhook(fakes: Fakes, webhook_url: str | None = "https://hooks.example/prism") -> str:
    """A job that ended with its webhook due; the fake clock set to the time Redis dated it due
    (read back, not Redis's clock before the transition: a loaded machine can spend seconds
    between the two)."""
    fakes.clock.now = fakes.store.server_time()
    job_id = fakes.job(items=1, state=State.running, webhook_url=webhook_url)
    assert fakes.store.transition(job_id, State.succeeded)
    due = fakes.store.webhook_due_since(job_id)
    if due is not None:
        fakes.clock.now = due
    return job_id


def test_a_webhook_delivery_lost_with_the_broker_is_sent_again_once(fakes: Fakes) -> None:
    job_id = _ended_with_a_webhook(fakes)
    now = fakes.clock.now  # the time it became due
    silent = _ended_with_a_webhook(fakes, webhook_url=None)  # nothing to deliver: never due
    assert watchdog.resend_webhooks(fakes.ctx, now + STALL - 5) == 0  # its task may be on its way
    fakes.redis.lpush("webhooks", _message(job_id))
    assert watchdog.resend_webhooks(fakes.ctx, now + STALL + 5) == 0  # queued: waiting its turn
    fakes.redis.delete("webhooks")  # the message lost (Redis's last second, AOF everysec)
    assert watchdog.resend_webhooks(fakes.ctx, now + STALL + 5) == 1
    assert fakes.sent.take() == [(TASK_DELIVER_WEBHOOK, (job_id,))]
    # Sent again: due again from now, so the next sweeps leave the new task its time.
    assert watchdog.resend_webhooks(fakes.ctx, now + STALL + 10) == 0
    assert watchdog.resend_webhooks(fakes.ctx, now + 2 * STALL + 10) == 1
    fakes.sent.take()
    fakes.store.webhook_done(job_id)  # delivered (or given up)
    # Delivered between the sweep's list and its look at the broker: not sent again.
    assert not fakes.store.webhook_resent(job_id, now + 10 * STALL)
    assert watchdog.resend_webhooks(fakes.ctx, now + 10 * STALL) == 0
    assert fakes.sent.sent == [] and silent not in fakes.store.webhooks_due(now + 10 * STALL)


def test_a_deleted_job_has_no_webhook_due(fakes: Fakes) -> None:
    job_id = _ended_with_a_webhook(fakes)
    assert fakes.store.webhooks_due(fakes.clock.now + 1) == [job_id]
    assert fakes.store.delete_job(job_id)
    assert fakes.store.webhooks_due(fakes.clock.now + 1) == []


def test_a_job_whose_own_task_gave_up_tells_its_client(fakes: Fakes) -> None:
    job_id = fakes.job(items=1, state=State.running, webhook_url="https://hooks.example/prism")
    quiet = fakes.job(items=1, state=State.running)
    lifecycle.job_failed(fakes.ctx, job_id, "run_job gave up")
    lifecycle.job_failed(fakes.ctx, quiet, "run_job gave up")
    lifecycle.job_failed(fakes.ctx, job_id, "told once")  # already failed: nothing more
    assert fakes.sent.take() == [(TASK_DELIVER_WEBHOOK, (job_id,))]
    assert fakes.store.state(job_id) == fakes.store.state(quiet) == State.failed

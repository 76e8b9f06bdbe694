"""The watchdog's policy, run in this process on the real Redis and SeaweedFS with a clock the test
moves (no worker consumes here: the messages it re-sends stay in the queue for the test to read).
The end-to-end recovery by a worker's own watchdog thread is in test_faults.py.
"""

from __future__ import annotations

import importlib
import json
import uuid
from dataclasses import replace
from datetime import UTC, datetime, timedelta

import pytest
import redis
from prism_common.queue import make_celery
from prism_common.records import ItemRecord, JobRecord, State
from prism_common.settings import Settings, get_settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore
from prism_common.upload_keys import frame_png_key, upload_key, video_info_key
from pydantic import ValidationError

from prism_worker.context import build_context
from prismcore import ScanSpec

from .servers import service_env

STALL, MAX_AGE = 100, 10_000
SPEC = ScanSpec.model_validate({"image": "upload:" + "0" * 32,
                                "points": [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]})


@pytest.fixture(scope="module")
def wd(redis_server, s3_server):
    """prism_worker's watchdog, configured (through the environment, as a worker is) for a
    Redis database and a bucket of its own."""
    env = service_env(redis_server.port, s3_server.port, db=7, bucket="t-watchdog",
                      JOB_STALL_TIMEOUT_S=str(STALL), JOB_STALL_RESTARTS="1", JOB_MAX_AGE_S=str(MAX_AGE))
    with pytest.MonkeyPatch.context() as mp:
        for name, value in env.items():
            mp.setenv(name, value)
        get_settings.cache_clear()
        watchdog = importlib.import_module("prism_worker.watchdog")
        settings = get_settings()
        celery = make_celery(settings)  # what the watchdog re-sends stays in this Redis's queue
        ctx = build_context(settings, celery.send_task)
        client = redis.Redis.from_url(settings.redis_url, decode_responses=True)
        client.flushdb()
        ObjectStore.from_settings(settings).ensure_bucket()
        yield watchdog, ctx, client
        client.flushdb()
        celery.close()
    get_settings.cache_clear()


def _job(client: redis.Redis, *, state: State, items: int = 1, age_s: float = 0, claimed: int = 0) -> str:
    store = JobStore(client)
    job = JobRecord(id=uuid.uuid4().hex, tenant="acme",
                    created_at=datetime.now(UTC) - timedelta(seconds=age_s),
                    items=[ItemRecord(index=i, spec=SPEC) for i in range(items)])
    store.create(job)
    if state != State.queued:
        store.transition(job.id, state)
    for _ in range(claimed):
        store.next_item(job.id)
    return job.id


def _queued_for(client: redis.Redis, job_id: str) -> list[str]:
    return [json.loads(m)["headers"]["task"] for m in client.lrange("scans", 0, -1) if job_id in m]


def test_a_job_waiting_its_turn_is_left_alone(wd):
    watchdog, ctx, client = wd
    job_id = _job(client, state=State.queued)
    client.lpush("scans", json.dumps({"headers": {"task": "prism.run_job", "argsrepr": f"['{job_id}']"}}))
    now = datetime.now(UTC).timestamp()
    for t in (now, now + STALL + 1, now + 3 * STALL):
        watchdog.sweep(ctx, t)
    assert JobStore(client).state(job_id) == State.queued
    assert _queued_for(client, job_id) == ["prism.run_job"]  # nothing re-sent
    client.delete("scans")


def test_a_stalled_job_is_restarted_then_failed_with_the_reason(wd):
    watchdog, ctx, client = wd
    settings = ctx.settings
    store = JobStore(client)
    job_id = _job(client, state=State.running, items=3, claimed=2)  # items 0, 1 started
    store.put_item(job_id, store.get(job_id).items[1].model_copy(update={"state": State.succeeded}))
    now = datetime.now(UTC).timestamp()
    watchdog.sweep(ctx, now)
    watchdog.sweep(ctx, now + STALL - 1)
    assert _queued_for(client, job_id) == []  # not stalled yet
    counts = watchdog.sweep(ctx, now + STALL + 1)
    assert counts["restarted"] == 1
    # Item 0 is started again from its plan; item 1 has an outcome: only its completion is re-sent.
    sent = [(json.loads(m)["headers"]["task"], json.loads(m)["headers"]["argsrepr"])
            for m in client.lrange("scans", 0, -1)]
    assert sorted(sent) == sorted([("prism.plan_item", f"('{job_id}', 0)"),
                                   ("prism.finish_item", f"([], '{job_id}', 1)")])
    # While those wait in the queue the job is not stalled, however long.
    assert watchdog.sweep(ctx, now + 5 * STALL)["failed"] == 0
    client.delete("scans")  # the re-sent work is lost too
    watchdog.sweep(ctx, now + 7 * STALL)
    job = store.get(job_id)
    assert job.state == State.failed
    assert job.error == f"stalled: no progress for {STALL} s, 1 restarts did not help"
    assert [i.state for i in job.items] == [State.failed, State.succeeded, State.failed]
    assert job.items[0].error == job.error
    saved = json.loads(ObjectStore.from_settings(settings).get_bytes(f"jobs/{job_id}/job.json"))
    assert saved["state"] == "failed" and saved["error"] == job.error


def test_progress_resets_the_clock(wd):
    watchdog, ctx, client = wd
    job_id = _job(client, state=State.running, claimed=1)
    now = datetime.now(UTC).timestamp()
    watchdog.sweep(ctx, now)
    for step in range(1, 4):  # a unit of progress before each stall would be declared
        client.hincrby(f"prism:job:{job_id}", "units_done", 1)
        assert watchdog.sweep(ctx, now + step * (STALL - 1))["restarted"] == 0
    assert _queued_for(client, job_id) == []
    assert JobStore(client).state(job_id) == State.running


def test_a_queued_job_whose_message_was_lost_is_sent_again(wd):
    watchdog, ctx, client = wd
    job_id = _job(client, state=State.queued)
    now = datetime.now(UTC).timestamp()
    watchdog.sweep(ctx, now)
    watchdog.sweep(ctx, now + STALL + 1)
    assert _queued_for(client, job_id) == ["prism.run_job"]
    client.delete("scans")


def test_jobs_past_the_maximum_age_fail(wd):
    watchdog, ctx, client = wd
    old = _job(client, state=State.running, age_s=MAX_AGE + 5)
    young = _job(client, state=State.queued, age_s=MAX_AGE - 60)
    client.lpush("scans", json.dumps({"headers": {"argsrepr": f"['{old}', 0]"}}))  # busy, still
    watchdog.sweep(ctx, datetime.now(UTC).timestamp())
    store = JobStore(client)
    assert store.state(old) == State.failed
    assert store.get(old).error == f"not finished {MAX_AGE} s after it was submitted"
    assert store.state(young) == State.queued
    client.delete("scans")


def test_one_sweep_per_interval_across_workers(wd):
    watchdog, ctx, client = wd
    settings = ctx.settings
    client.delete(watchdog.LOCK_KEY)
    assert watchdog.try_sweep(ctx, "worker-a") is not None
    assert watchdog.try_sweep(ctx, "worker-b") is None  # a's lock holds for the interval
    assert client.get(watchdog.LOCK_KEY) == "worker-a"
    assert 0 < client.ttl(watchdog.LOCK_KEY) <= settings.watchdog_interval_s


def test_uploads_past_their_ttl_are_deleted_with_their_frames(wd):
    watchdog, ctx, client = wd
    settings = ctx.settings
    retention = importlib.import_module("prism_worker.watchdog")  # retention is part of the sweep
    store, objects = JobStore(client), ObjectStore.from_settings(settings)
    ids = {"old": uuid.uuid4().hex, "new": uuid.uuid4().hex, "unlisted": uuid.uuid4().hex}
    for upload_id in ids.values():
        key = upload_key("acme", upload_id)
        store.put_upload(upload_id, tenant="acme", key=key, size=3, name="clip.avi")
        for k in (key, video_info_key("acme", upload_id), frame_png_key("acme", upload_id, 0),
                  frame_png_key("acme", upload_id, 7)):
            objects.put_bytes(k, b"abc")
    objects.put_bytes(f"jobs/{uuid.uuid4().hex}/items/0/cloud.csv", b"1,2,3\n")  # a job's output
    before = set(objects.list_keys(""))
    now = datetime.now(UTC).timestamp()
    client.zadd("prism:uploads", {ids["old"]: now - settings.upload_ttl_s - 5})  # made long ago
    # One made long ago by a version that did not list uploads for expiry.
    client.zrem("prism:uploads", ids["unlisted"])
    long_ago = datetime.fromtimestamp(now - settings.upload_ttl_s - 60, UTC).isoformat()
    client.hset(f"prism:upload:{ids['unlisted']}", "created_at", long_ago)

    retention._indexed = False  # as in a worker process just started
    client.delete(watchdog.LOCK_KEY)
    counts = watchdog.try_sweep(ctx, "test")  # the sweep expires uploads too
    assert counts["uploads expired"] == 2
    gone = {k for k in before if ids["old"] in k or ids["unlisted"] in k}
    assert len(gone) == 8 and set(objects.list_keys("")) == before - gone
    assert store.get_upload(ids["old"]) is None and store.get_upload(ids["unlisted"]) is None
    assert store.get_upload(ids["new"]) is not None
    assert retention.expire_uploads(ctx, now) == 0  # nothing left to do: idempotent


@pytest.mark.parametrize("name", ["upload_ttl_s", "job_ttl_s"])
def test_a_lifetime_shorter_than_a_job_may_live_is_refused(name):
    with pytest.raises(ValidationError, match=f"{name}=3600 is shorter than job_max_age_s=86400"):
        Settings(api_keys={"a": "k"}, webhook_secret="s", job_max_age_s=86400, **{name: 3600})
    assert getattr(Settings(api_keys={"a": "k"}, webhook_secret="s", job_max_age_s=86400,
                            **{name: 0}), name) == 0


def test_ended_jobs_past_their_ttl_are_deleted_when_one_is_set(wd):
    _, ctx, client = wd
    settings = ctx.settings
    retention = importlib.import_module("prism_worker.watchdog")  # retention is part of the sweep
    store, objects = JobStore(client), ObjectStore.from_settings(settings)
    day = 86_400
    ttl = settings.model_copy(update={"job_ttl_s": 30 * day})
    old_done = _job(client, state=State.succeeded, items=2, age_s=31 * day)
    old_running = _job(client, state=State.running, age_s=31 * day)  # never deleted
    recent_done = _job(client, state=State.failed, age_s=29 * day)
    for job_id in (old_done, old_running, recent_done):
        for name in ("job.json", "items/0/cloud.csv", "items/1/frame_000002/cloud.ply"):
            objects.put_bytes(f"jobs/{job_id}/{name}", b"x")
    store.tile_done(old_done, 0, "front-0-10")
    store.item_done(old_done, 1)
    now = datetime.now(UTC).timestamp()

    assert retention.expire_jobs(ctx, now) == 0  # job_ttl_s 0 (the default): kept
    assert retention.expire_jobs(replace(ctx, settings=ttl), now) == 1
    assert objects.list_keys(f"jobs/{old_done}/") == []
    for kept in (old_running, recent_done):
        assert len(objects.list_keys(f"jobs/{kept}/")) == 3
    assert store.get(old_done) is None and store.get(old_running) and store.get(recent_done)
    assert not [k for k in client.scan_iter(match=f"*{old_done}*")]  # no key of it is left
    listed = {j.id for j, _ in store.list("acme", limit=200)[0]}
    assert old_done not in listed and {old_running, recent_done} <= listed
    assert retention.expire_jobs(replace(ctx, settings=ttl), now) == 0  # idempotent

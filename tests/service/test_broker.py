"""prism_worker.broker reads kombu's own Redis structures (the queue lists, their priority
siblings, the ``unacked`` hash). This test publishes real messages through Celery into a real
Redis and takes one as a worker does, so it fails when a kombu release changes what the module
relies on (kombu is pinned in pyproject.toml for that reason)."""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import pytest
import redis
from celery import Celery
from prism_common.queue import (
    QUEUE_SCANS,
    TASK_DELIVER_WEBHOOK,
    TASK_PLAN_ITEM,
    TASK_RUN_JOB,
    make_celery,
    queue_lists,
)
from prism_common.settings import Settings

from prism_worker.broker import UNACKED_HASH, pending_job_ids

DB = 13


@pytest.fixture
def broker(redis_server) -> Iterator[tuple[Celery, redis.Redis]]:
    url = f"redis://127.0.0.1:{redis_server.port}/{DB}"
    app = make_celery(Settings(api_keys={"a": "k"}, webhook_secret="s", redis_url=url))
    client = redis.Redis.from_url(url, decode_responses=True)
    client.flushdb()
    yield app, client
    client.flushdb()
    client.close()
    app.close()


def test_waiting_messages_are_found_in_every_queue_and_priority(broker) -> None:
    app, client = broker
    plain, urgent, hook = (uuid.uuid4().hex for _ in range(3))
    app.send_task(TASK_PLAN_ITEM, (plain, 0))
    app.send_task(TASK_RUN_JOB, (urgent,), priority=3)
    app.send_task(TASK_DELIVER_WEBHOOK, (hook,))
    assert client.llen(QUEUE_SCANS) == 1 and client.llen(queue_lists(QUEUE_SCANS)[1]) == 1
    assert pending_job_ids(client) == {plain, urgent, hook}


def test_a_message_taken_but_not_acknowledged_is_found_until_it_is(broker) -> None:
    app, client = broker
    job_id = uuid.uuid4().hex
    app.send_task(TASK_PLAN_ITEM, (job_id, 3), countdown=60)  # as a retry waits
    with app.connection_for_read() as conn:
        queue = conn.SimpleQueue(QUEUE_SCANS)
        message = queue.get(timeout=10)  # taken, as a worker takes it
        assert client.llen(QUEUE_SCANS) == 0 and client.hlen(UNACKED_HASH) == 1
        assert pending_job_ids(client) == {job_id}
        message.ack()
        queue.close()
    assert pending_job_ids(client) == set()


def test_other_ids_in_the_arguments_are_not_mistaken_for_jobs(broker) -> None:
    app, client = broker
    job_id = uuid.uuid4().hex
    app.send_task(TASK_PLAN_ITEM, ([], job_id, 1))  # finish_item's shape: the id is not first
    app.send_task(TASK_PLAN_ITEM, ("not-a-job-" + "a" * 31, 0))
    assert pending_job_ids(client) == {job_id}

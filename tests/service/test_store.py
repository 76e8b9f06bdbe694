"""The job store against a real Redis: records, transitions, idempotency, listing, restart."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime, timedelta

import pytest
from prism_common.records import FrameRecord, ItemRecord, JobRecord, State
from prism_common.store import IdempotencyConflictError

from prismcore.spec import FrameSelection, ScanSpec

SPEC = ScanSpec(image="upload:abc", points=[[1, 1], [9, 1], [9, 9], [9, 1], [12, 1]])


def _job(tenant: str = "acme", minutes: int = 0) -> JobRecord:
    return JobRecord(id=uuid.uuid4().hex, tenant=tenant, items=[ItemRecord(index=0, spec=SPEC)],
                     created_at=datetime.now(UTC) + timedelta(minutes=minutes))


def test_create_get_round_trip(store):
    job, created = store.create(_job())
    assert created and store.get(job.id) == job
    assert job.state == State.queued and job.progress == 0


@pytest.mark.parametrize(
    ("path", "final"),
    [(["running", "succeeded"], "succeeded"), (["running", "queued"], "running"),
     (["cancelled", "running", "succeeded"], "cancelled"), (["failed", "succeeded"], "failed"),
     (["running", "completed_with_failures", "succeeded", "failed"], "completed_with_failures"),
     (["running", "succeeded", "completed_with_failures"], "succeeded")],
)
def test_state_never_goes_backwards(store, path, final):
    job, _ = store.create(_job())
    for state in path:
        store.transition(job.id, State(state))
    assert store.get(job.id).state == State(final)


def test_idempotency_same_body_same_job_other_body_conflicts(store):
    first, created = store.create(_job(), idempotency_key="k1", body=b"{}")
    again, created_again = store.create(_job(), idempotency_key="k1", body=b"{}")
    assert created and not created_again and again.id == first.id
    with pytest.raises(IdempotencyConflictError):
        store.create(_job(), idempotency_key="k1", body=b"{other}")
    other_tenant, created = store.create(_job("globex"), idempotency_key="k1", body=b"{}")
    assert created and other_tenant.id != first.id


def test_list_newest_first_with_cursor_and_state(store):
    tenant = "list-" + uuid.uuid4().hex[:6]
    ids = [store.create(_job(tenant, minutes=i))[0].id for i in range(7)]
    store.transition(ids[3], State.running)
    page, cursor = store.list(tenant, limit=3)
    seen = [j.id for j, _ in page]
    while cursor is not None:
        page, cursor = store.list(tenant, limit=3, cursor=cursor)
        seen += [j.id for j, _ in page]
    assert seen == ids[::-1]
    running, _ = store.list(tenant, state=State.running)
    assert [(j.id, n) for j, n in running] == [(ids[3], 1)]
    # Without items: the same jobs and facts, no items, their count kept.
    bare, _ = store.list(tenant, limit=7, items=False)
    whole, _ = store.list(tenant, limit=7)
    assert [(j.model_dump(exclude={"items"}), n) for j, n in bare] == [
        (j.model_dump(exclude={"items"}), n) for j, n in whole]
    assert all(j.items == [] for j, _ in bare) and all(len(j.items) == n == 1 for j, n in whole)


def test_tiles_count_once_and_progress(store):
    job, _ = store.create(_job())
    assert store.tile_done(job.id, 0, "front-0-10") and not store.tile_done(job.id, 0, "front-0-10")
    assert 0 < store.get(job.id).progress < 100
    assert store.item_done(job.id, 0) == 1 and store.item_done(job.id, 0) == 1


def test_records_survive_a_redis_restart(store, redis_server):
    job, _ = store.create(_job())
    store.transition(job.id, State.running)
    redis_server.restart()
    assert store.get(job.id).state == State.running


def test_get_item_reads_one_item_with_its_jobs_facts(store):
    job = JobRecord(id=uuid.uuid4().hex, tenant="acme", created_at=datetime.now(UTC),
                    items=[ItemRecord(index=i, spec=SPEC.model_copy(update={"image": f"upload:{i}"}))
                           for i in range(3)])
    store.create(job)
    store.transition(job.id, State.running)
    done = job.items[1].model_copy(update={"state": State.failed, "error": "bad photo"})
    store.put_item(job.id, done)
    view = store.get_item(job.id, 1)
    assert (view.job_id, view.tenant, view.state, view.n_items) == (job.id, "acme", State.running, 3)
    assert view.item == done
    assert store.get_item(job.id, 2).item == job.items[2]
    assert store.get(job.id).items == [job.items[0], done, job.items[2]]  # the same truth
    assert store.get_item(job.id, 3) is None and store.get_item(uuid.uuid4().hex, 0) is None


@pytest.mark.parametrize(("offset", "limit"), [(0, 7), (2, 3), (3, 1), (5, 10), (7, 5), (0, 0), (99, 1)])
def test_a_page_of_items_is_the_same_slice_as_the_whole_job(store, offset, limit):
    # Items 3 and 5 are videos with frames (stored as fields of their own), one frame left out
    # of order, so the page must find and sort them as the whole read does.
    video = SPEC.model_copy(update={"image": "upload:v", "frames": FrameSelection(every=2)})
    job = JobRecord(id=uuid.uuid4().hex, tenant="acme", created_at=datetime.now(UTC),
                    items=[ItemRecord(index=i, spec=video if i in (3, 5) else SPEC) for i in range(7)])
    store.create(job)
    store.transition(job.id, State.running)
    for item, frames in ((3, (4, 0, 2)), (5, (10,))):
        for n in frames:
            store.put_frame(job.id, item, FrameRecord(index=n, state=State.succeeded))
    store.put_item(job.id, job.items[6].model_copy(update={"state": State.failed, "error": "x"}))
    whole = store.get(job.id)
    page, count = store.get_page(job.id, offset, limit)
    assert count == 7
    assert page.items == whole.items[offset:offset + limit]
    assert page.model_dump(exclude={"items"}) == whole.model_dump(exclude={"items"})
    assert [f.index for f in whole.items[3].frames] == [0, 2, 4]
    assert store.get_page(uuid.uuid4().hex, 0, 1) is None


def test_a_page_of_a_large_video_job_reads_its_frames_once(store):
    # 300 items and 600 frame fields: a hash Redis scans in several steps, not one reply.
    video = SPEC.model_copy(update={"image": "upload:v", "frames": FrameSelection(every=2)})
    job = JobRecord(id=uuid.uuid4().hex, tenant="acme", created_at=datetime.now(UTC),
                    items=[ItemRecord(index=i, spec=video) for i in range(300)])
    store.create(job)
    for i in range(300):
        for n in (4, 2):
            store.put_frame(job.id, i, FrameRecord(index=n, state=State.succeeded))
    whole = store.get(job.id)
    page, _ = store.get_page(job.id, 150, 100)
    assert page.items == whole.items[150:250]
    assert all([f.index for f in item.frames] == [2, 4] for item in page.items)

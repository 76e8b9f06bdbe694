"""In-memory fakes for the worker's logic, injected through `WorkerContext`: the job store on
fakeredis (which runs the store's Lua scripts too, through lupa), a bucket in a dict, a clock the
test moves and a task sender that records what would have been sent. No Redis server, no bucket,
no worker process.
"""

from __future__ import annotations

import io
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

import fakeredis
import pytest
from botocore.exceptions import ClientError
from prism_common.records import ItemRecord, JobRecord, State
from prism_common.settings import Settings
from prism_common.storage import ObjectStore
from prism_common.store import JobStore

from prism_worker.context import WorkerContext
from prismcore import ScanSpec

SPEC = ScanSpec.model_validate({"image": "upload:" + "0" * 32,
                                "points": [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]})


def _missing(key: str) -> ClientError:
    return ClientError({"Error": {"Code": "NoSuchKey", "Message": key}}, "GetObject")


class _S3Client:
    """The one boto3 call the worker makes itself (get_object, to stream an input): over the
    store's dict for its own bucket, `other` for the rest."""

    def __init__(self, store: MemoryObjectStore) -> None:
        self._store = store
        self.other: dict[str, dict[str, bytes]] = {}

    def get_object(self, *, Bucket: str, Key: str, Range: str | None = None) -> dict[str, Any]:
        if Bucket == self._store.bucket:
            data = self._store.objects[Key][0] if Key in self._store.objects else None
        else:
            data = self.other.get(Bucket, {}).get(Key)
        if data is None:
            raise _missing(Key)
        if Range is not None:
            first, last = (int(n) for n in Range.removeprefix("bytes=").split("-"))
            data = data[first:last + 1]
        return {"Body": io.BytesIO(data), "ContentLength": len(data)}


class MemoryObjectStore(ObjectStore):
    """The bucket's interface over a dict: key -> (bytes, content type)."""

    def __init__(self, bucket: str = "test-bucket") -> None:
        self.objects: dict[str, tuple[bytes, str]] = {}
        super().__init__(client=_S3Client(self), bucket=bucket)

    def ensure_bucket(self) -> None:
        pass

    def put_bytes(self, key: str, data: bytes, content_type: str = "application/octet-stream") -> None:
        self.objects[key] = (bytes(data), content_type)

    def put_stream(self, key: str, stream: Any, content_type: str = "application/octet-stream") -> None:
        self.objects[key] = (stream.read(), content_type)

    def get_bytes(self, key: str, *, bucket: str | None = None) -> bytes:
        if key not in self.objects:
            raise _missing(key)
        return self.objects[key][0]

    def get_head(self, key: str, size: int) -> bytes:
        return self.get_bytes(key)[:size]

    def open(self, key: str) -> tuple[Any, int]:
        data = self.get_bytes(key)
        return io.BytesIO(data), len(data)

    def exists(self, key: str) -> bool:
        return key in self.objects

    def list_keys(self, prefix: str) -> list[str]:
        return sorted(k for k in self.objects if k.startswith(prefix))

    def delete_keys(self, keys: list[str]) -> None:
        for key in keys:
            self.objects.pop(key, None)

    def presign_get(self, key: str, ttl_s: int, filename: str | None = None) -> str:
        return f"https://links.test/{self.bucket}/{key}?ttl={ttl_s}"


class FakeClock:
    """Seconds since the epoch, moved by the test."""

    def __init__(self, now: float = 1_800_000_000.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> float:
        self.now += seconds
        return self.now


@dataclass
class SentTasks:
    """Records `send_task` calls: (task name, args) in order, options beside."""

    sent: list[tuple[str, tuple[Any, ...]]] = field(default_factory=list)
    options: list[dict[str, Any]] = field(default_factory=list)

    def __call__(self, name: str, args: Sequence[Any] = (), **options: Any) -> object:
        self.sent.append((name, tuple(args)))
        self.options.append(options)
        return None

    def names(self) -> list[str]:
        return [name for name, _ in self.sent]

    def take(self) -> list[tuple[str, tuple[Any, ...]]]:
        """What was sent since the last take."""
        taken, self.sent[:] = list(self.sent), []
        self.options.clear()
        return taken


def make_settings(**overrides: Any) -> Settings:
    values: dict[str, Any] = {"api_keys": {"acme": "k"}, "webhook_secret": "s",
                              "items_in_flight_per_job": 2, "tiles_per_face": 4,
                              "job_stall_timeout_s": 100, "job_stall_restarts": 1,
                              "job_max_age_s": 10_000, "watchdog_interval_s": 5}
    return Settings(**(values | overrides))


@dataclass
class Fakes:
    ctx: WorkerContext
    redis: fakeredis.FakeRedis
    store: JobStore
    objects: MemoryObjectStore
    clock: FakeClock
    sent: SentTasks

    def with_settings(self, **overrides: Any) -> Fakes:
        from dataclasses import replace
        settings = self.ctx.settings.model_copy(update=overrides)
        return replace(self, ctx=replace(self.ctx, settings=settings))

    def upload(self, data: bytes, *, name: str = "box.jpg", tenant: str = "acme") -> str:
        """A stored upload of `data`; its reference (``upload:{id}``)."""
        upload_id = uuid.uuid4().hex
        key = f"uploads/{tenant}/{upload_id}"
        self.objects.put_bytes(key, data)
        self.store.put_upload(upload_id, tenant=tenant, key=key, size=len(data), name=name)
        return f"upload:{upload_id}"

    def job(self, *, items: int = 1, state: State = State.queued, age_s: float = 0,
            webhook_url: str | None = None, spec: ScanSpec = SPEC) -> str:
        """A stored job of `items` items, created `age_s` before the clock's now."""
        created = datetime.fromtimestamp(self.clock.now, UTC) - timedelta(seconds=age_s)
        job = JobRecord(id=uuid.uuid4().hex, tenant="acme", created_at=created, webhook_url=webhook_url,
                        items=[ItemRecord(index=i, spec=spec) for i in range(items)])
        self.store.create(job)
        if state != State.queued:
            self.store.transition(job.id, state)
        return job.id


@pytest.fixture
def fakes() -> Iterator[Fakes]:
    client = fakeredis.FakeRedis(decode_responses=True)
    store, objects, clock, sent = JobStore(client), MemoryObjectStore(), FakeClock(), SentTasks()
    ctx = WorkerContext(settings=make_settings(), redis=client, store=store, objects=objects,
                        link_objects=objects, clock=clock, send_task=sent)
    yield Fakes(ctx, client, store, objects, clock, sent)
    client.flushall()



"""The job store: job records in Redis, updated atomically by the API and the workers.

Layout (all keys under ``prism:``):

* ``job:{id}`` hash: ``doc`` (the record as submitted, without its items), ``n_items``,
  ``item:{i}`` (each item: its spec, state, error, result and outputs), ``state``, timestamps,
  ``error``, ``units_total``/``units_done``/``items_planned`` (progress, see `progress`;
  ``units_at_cancel``: "done/total/planned" when the job was cancelled, what its progress stays
  at), ``tenant``. Items are fields of their own so that a task about one item of a 5000-item
  job reads that item, not the whole job.
* ``frame:{i}:{n}`` fields of the same hash: frame n of video item i (written by its own task,
  so frames finishing at once never overwrite each other); ``job:{id}:frames`` hash: item ->
  frames selected (for the cap per job); ``job:{id}:frames:{i}`` set of finished frames.
* ``job:{id}:tiles:{i}`` set of finished tiles, ``job:{id}:done`` set of finished items,
  ``job:{id}:next`` the next item to start: counting by set membership makes a re-run task
  count once.
* ``tenant:{t}:jobs`` and ``tenant:{t}:state:{s}`` sorted sets (score: creation time, us), and
  ``state:{s}`` across tenants (for metrics).
* ``idem:{t}:{key}`` the job an idempotency key made. Uploads: see upload_records.py.
* ``watch:{id}`` hash: what the watchdog saw of a running job at its last sweep (``units``,
  ``since``, ``restarts``); ``watchdog:lock``: the sweep of the current interval is taken.

A state never goes backwards: transitions run in one Lua script that compares ranks.
"""

from __future__ import annotations

import builtins
import hashlib
import json
from datetime import UTC, datetime
from typing import cast

import redis
from redis.typing import EncodableT, FieldT

from .records import FINAL_STATES, FrameRecord, ItemRecord, ItemView, JobRecord, State
from .redis_client import redis_client
from .settings import Settings
from .upload_records import UploadRecords

__all__ = ["UNITS_PER_ITEM_ESTIMATE", "WATCHDOG_LOCK_KEY", "IdempotencyConflictError", "JobStore",
           "progress"]

_P = "prism:"
_WEBHOOKS_DUE = f"{_P}webhooks:due"  # job id -> since when (s) its webhook is due
# A job hash's fields other than its items and frames.
_VERDICT_FIELDS = ["verdict:pass", "verdict:fail", "verdict:uncertain"]
_JOB_FIELDS = ["doc", "n_items", "state", "started_at", "finished_at", "error", "units_total",
               "units_done", "items_planned", "units_at_cancel", "items_done", "items_failed",
               *_VERDICT_FIELDS]
UNITS_PER_ITEM_ESTIMATE = 10  # plan + finish + tiles, until the plan knows the tile count
WATCHDOG_LOCK_KEY = f"{_P}watchdog:lock"
_RANK = {"queued": 0, "running": 1, "succeeded": 2, "completed_with_failures": 2, "failed": 2,
         "cancelled": 2}

# The one state machine of a job: queued -> running -> one final state (succeeded,
# completed_with_failures, failed: ended by its items; cancelled), never backwards nor from one
# final state to another. Which ended state is lifecycle._end_job's decision.
_TRANSITION = """
local cur = redis.call('HGET', KEYS[1], 'state')
if not cur then return 0 end
local rank = {queued=0, running=1, succeeded=2, completed_with_failures=2, failed=2, cancelled=2}
if not rank[ARGV[1]] then return redis.error_reply('unknown state ' .. ARGV[1]) end
if rank[ARGV[1]] <= rank[cur] then return 0 end
redis.call('HSET', KEYS[1], 'state', ARGV[1])
if ARGV[1] == 'running' then redis.call('HSET', KEYS[1], 'started_at', ARGV[2]) end
if rank[ARGV[1]] == 2 then redis.call('HSET', KEYS[1], 'finished_at', ARGV[2]) end
if ARGV[1] == 'cancelled' then
  -- What had finished when the job was cancelled; tasks in flight may still count units after.
  local done = redis.call('HGET', KEYS[1], 'units_done') or '0'
  local total = redis.call('HGET', KEYS[1], 'units_total') or '1'
  local planned = redis.call('HGET', KEYS[1], 'items_planned') or '0'
  redis.call('HSET', KEYS[1], 'units_at_cancel', done .. '/' .. total .. '/' .. planned)
end
if ARGV[3] ~= '' then redis.call('HSET', KEYS[1], 'error', ARGV[3]) end
if rank[ARGV[1]] == 2 and ARGV[1] ~= 'cancelled' and redis.call('HGET', KEYS[1], 'webhook') == '1' then
  -- Its webhook is due, written with the ending itself: a delivery task lost with Redis's last
  -- second (AOF everysec) is sent again by the watchdog, not forgotten.
  local t = redis.call('TIME')
  redis.call('ZADD', ARGV[5] .. 'webhooks:due', tonumber(t[1]), ARGV[4])
end
local tenant = redis.call('HGET', KEYS[1], 'tenant')
local score = redis.call('HGET', KEYS[1], 'score')
local id = ARGV[4]
redis.call('ZREM', ARGV[5] .. 'tenant:' .. tenant .. ':state:' .. cur, id)
redis.call('ZADD', ARGV[5] .. 'tenant:' .. tenant .. ':state:' .. ARGV[1], score, id)
redis.call('ZREM', ARGV[5] .. 'state:' .. cur, id)
redis.call('ZADD', ARGV[5] .. 'state:' .. ARGV[1], score, id)
return 1
"""

_TILE_DONE = """
if redis.call('SADD', KEYS[2], ARGV[1]) == 1 then
  redis.call('HINCRBY', KEYS[1], 'units_done', 1)
  if tonumber(ARGV[2]) ~= 0 then redis.call('HINCRBY', KEYS[1], 'units_total', ARGV[2]) end
  if tonumber(ARGV[3]) ~= 0 then redis.call('HINCRBY', KEYS[1], 'items_planned', ARGV[3]) end
  return 1
end
return 0
"""


# The set says which items finished (a redelivered task finds its item there); the job hash's
# count is what a poll reads without touching the set; so are the count of its verdict (ARGV[2])
# and of the failed items (ARGV[3] '1': this item failed).
_ITEM_DONE = """
if redis.call('SADD', KEYS[2], ARGV[1]) == 1 then
  redis.call('HINCRBY', KEYS[1], 'items_done', 1)
  if ARGV[2] ~= '' then redis.call('HINCRBY', KEYS[1], 'verdict:' .. ARGV[2], 1) end
  if ARGV[3] == '1' then redis.call('HINCRBY', KEYS[1], 'items_failed', 1) end
end
return redis.call('SCARD', KEYS[2])
"""


class IdempotencyConflictError(Exception):
    """The idempotency key was used before with a different request body."""


def _now() -> datetime:
    return datetime.now(UTC)


class JobStore(UploadRecords):
    """Job records in Redis. Pass a client (tests give their own server's).

    The client must decode replies (``decode_responses=True``, as `from_url` makes it): replies
    are cast to str here. (`builtins.list` in annotations: the `list` method shadows it.)
    """

    def __init__(self, client: redis.Redis) -> None:
        self._r = client
        self._transition = client.register_script(_TRANSITION)
        self._tile_done = client.register_script(_TILE_DONE)
        self._item_done = client.register_script(_ITEM_DONE)

    @classmethod
    def from_settings(cls, settings: Settings) -> JobStore:
        return cls(redis_client(settings, health_check_interval=30))

    # -- jobs -------------------------------------------------------------------------------
    def create(self, job: JobRecord, *, idempotency_key: str | None = None,
               body: bytes = b"") -> tuple[JobRecord, bool]:
        """Store a new job, or return the one this idempotency key already made.

        Returns
        -------
        (job, created)

        Raises
        ------
        IdempotencyConflictError
            The key was used with a different body.
        """
        digest = hashlib.sha256(body).hexdigest()
        if idempotency_key:
            idem = _idem_key(job.tenant, idempotency_key)
            if not self._r.set(idem, f"{job.id} {digest}", nx=True, ex=7 * 86400):
                existing = self.find_idempotent(job.tenant, idempotency_key, body)
                if existing is not None:
                    return existing, False
                # The first request's job write never landed: this one takes the key over.
                self._r.set(idem, f"{job.id} {digest}", ex=7 * 86400)
        score = job.created_at.timestamp() * 1e6
        units = UNITS_PER_ITEM_ESTIMATE * len(job.items)
        with self._r.pipeline() as pipe:
            pipe.hset(f"{_P}job:{job.id}", mapping={
                "doc": job.model_dump_json(exclude={"items"}), "n_items": len(job.items),
                **{f"item:{item.index}": item.model_dump_json() for item in job.items},
                "state": State.queued.value,
                "tenant": job.tenant, "score": score, "units_total": units, "units_done": 0,
                "webhook": "1" if job.webhook_url else "0"})
            pipe.zadd(f"{_P}tenant:{job.tenant}:jobs", {job.id: score})
            pipe.zadd(f"{_P}tenant:{job.tenant}:state:queued", {job.id: score})
            pipe.zadd(f"{_P}state:queued", {job.id: score})
            pipe.execute()
        return job, True  # what get() would read back: queued, no progress, no timestamps

    def find_idempotent(self, tenant: str, idempotency_key: str, body: bytes) -> JobRecord | None:
        """The job this tenant's key already made, if any (and it was stored).

        Raises IdempotencyConflictError if the key was used with a different body.
        """
        found = cast("str | None", self._r.get(_idem_key(tenant, idempotency_key)))
        if found is None:
            return None
        existing_id, existing_digest = found.split(" ", 1)
        if existing_digest != hashlib.sha256(body).hexdigest():
            raise IdempotencyConflictError(
                "this Idempotency-Key was already used with a different request body")
        return self.get(existing_id)

    def get(self, job_id: str) -> JobRecord | None:
        """The job as it stands now, or None."""
        fields = cast("dict[str, str]", self._r.hgetall(f"{_P}job:{job_id}"))
        return _job(fields) if fields else None

    def get_page(self, job_id: str, offset: int, limit: int) -> tuple[JobRecord, int] | None:
        """The job with only its items offset..offset+limit-1 (fewer past the end), and how many
        items it has: a poll of a large job reads and parses only the page asked for."""
        key = f"{_P}job:{job_id}"
        fields = _job_fields(cast("builtins.list[str | None]", self._r.hmget(key, _JOB_FIELDS)))
        if "doc" not in fields:
            return None
        n = int(fields["n_items"])
        indices = range(min(offset, n), min(offset + limit, n))
        if indices:
            names = [f"item:{i}" for i in indices]
            fields.update(zip(names, cast("builtins.list[str]", self._r.hmget(key, names)), strict=True))
        job = _job(fields, indices)
        if any(item.spec.is_video for item in job.items):
            # Frames are fields of their own: one pass over the hash for the whole page (a scan
            # may return a field twice; the dict keeps it once), then only this page's are read.
            _attach_frames({item.index: item for item in job.items},
                           cast("dict[str, str]", dict(self._r.hscan_iter(key, match="frame:*", count=1000))))
        return job, n

    def get_item(self, job_id: str, index: int) -> ItemView | None:
        """One item and the job facts its tasks need, without reading the rest of the job."""
        state, tenant, n_items, item = cast("builtins.list[str | None]", self._r.hmget(
            f"{_P}job:{job_id}", ["state", "tenant", "n_items", f"item:{index}"]))
        if state is None or item is None or tenant is None or n_items is None:
            return None
        return ItemView(job_id=job_id, tenant=tenant, state=State(state), n_items=int(n_items),
                        item=ItemRecord.model_validate_json(item))

    def list(self, tenant: str, *, state: State | None = None, limit: int = 50,
             cursor: float | None = None, items: bool = True
             ) -> tuple[list[tuple[JobRecord, int]], float | None]:
        """The tenant's jobs, newest first, each with its number of items; and the next page's
        cursor. Without `items` the records hold none (a listing of big jobs stays small)."""
        key = f"{_P}tenant:{tenant}:state:{state.value}" if state else f"{_P}tenant:{tenant}:jobs"
        top = f"({cursor!r}" if cursor is not None else "+inf"
        rows = cast("builtins.list[tuple[str, float]]", self._r.zrevrangebyscore(
            key, top, "-inf", start=0, num=limit + 1, withscores=True))
        with self._r.pipeline(transaction=False) as pipe:
            for job_id, _ in rows[:limit]:
                if items:
                    pipe.hgetall(f"{_P}job:{job_id}")
                else:
                    pipe.hmget(f"{_P}job:{job_id}", _JOB_FIELDS)
            found = pipe.execute()
        if not items:
            found = [_job_fields(values) for values in found]
        jobs = [(_job(fields, None if items else range(0)), int(fields["n_items"]))
                for fields in found if fields]
        return jobs, (rows[limit - 1][1] if len(rows) > limit else None)

    def transition(self, job_id: str, state: State, *, error: str | None = None) -> bool:
        """Move the job forward to `state`; False (and no change) if that would go backwards."""
        return bool(self._transition(keys=[f"{_P}job:{job_id}"], args=[
            state.value, _now().isoformat(), error or "", job_id, _P]))

    def state(self, job_id: str) -> State | None:
        value = cast("str | None", self._r.hget(f"{_P}job:{job_id}", "state"))
        return State(value) if value else None

    def ended_before(self, when: float, limit: int = 200) -> builtins.list[str]:
        """Ids of up to `limit` final jobs (succeeded, completed_with_failures, failed,
        cancelled) submitted before `when` (s since the epoch), oldest first."""
        top = f"({when * 1e6!r}"
        ids: builtins.list[str] = []
        for state in FINAL_STATES:
            ids += cast("builtins.list[str]", self._r.zrangebyscore(
                f"{_P}state:{state.value}", "-inf", top, start=0, num=limit))
        return ids[:limit]

    def delete_job(self, job_id: str) -> bool:
        """Remove an ended job's record and every key and listing entry of it; False if there
        was no such job or it has not ended (a running job's record is never removed)."""
        key = f"{_P}job:{job_id}"
        tenant, state, n_items = cast("builtins.list[str | None]",
                                      self._r.hmget(key, "tenant", "state", "n_items"))
        if tenant is None or state is None or State(state) not in FINAL_STATES:
            return False
        per_item = [f"{key}:{kind}:{i}" for i in range(int(n_items or 0)) for kind in ("tiles", "frames")]
        with self._r.pipeline() as pipe:
            pipe.zrem(f"{_P}tenant:{tenant}:jobs", job_id)
            pipe.zrem(f"{_P}tenant:{tenant}:state:{state}", job_id)
            pipe.zrem(f"{_P}state:{state}", job_id)
            for start in range(0, len(per_item), 1000):
                pipe.delete(*per_item[start:start + 1000])
            pipe.delete(f"{key}:done", f"{key}:next", f"{key}:frames", f"{_P}watch:{job_id}", key)
            pipe.zrem(_WEBHOOKS_DUE, job_id)
            pipe.execute()
        return True

    # -- webhooks due -------------------------------------------------------------------------
    def webhooks_due(self, before: float) -> builtins.list[str]:
        """Jobs whose webhook has been due since before `before` (s, Redis's clock) and is not
        yet delivered or given up (`webhook_done`)."""
        return cast("builtins.list[str]", self._r.zrangebyscore(_WEBHOOKS_DUE, 0, before))

    def webhook_due_since(self, job_id: str) -> float | None:
        """Since when (s, Redis's clock) a job's webhook has been due; None when it is not due."""
        score = self._r.zscore(_WEBHOOKS_DUE, job_id)
        return None if score is None else float(score)

    def webhook_resent(self, job_id: str, now: float) -> bool:
        """A job's delivery is sent again at `now`: due again from then. False when it is no
        longer due (delivered meanwhile): then it is not to be sent."""
        return bool(self._r.zadd(_WEBHOOKS_DUE, {job_id: now}, xx=True, ch=True))

    def webhook_done(self, job_id: str) -> None:
        """A job's webhook was delivered, or given up: no longer due."""
        self._r.zrem(_WEBHOOKS_DUE, job_id)

    # -- items and progress -----------------------------------------------------------------
    def put_item(self, job_id: str, item: ItemRecord) -> None:
        self._r.hset(f"{_P}job:{job_id}", f"item:{item.index}", item.model_dump_json())

    def next_item(self, job_id: str) -> int:
        """Claim the next item to start (0, 1, 2, ...); each index is handed out once."""
        return int(self._r.incr(f"{_P}job:{job_id}:next")) - 1

    def add_units(self, job_id: str, *, total: int = 0, done: int = 0) -> None:
        """Add to the job's units (`total`, `done`); an item's plan counts through `tile_done`."""
        with self._r.pipeline() as pipe:
            if total:
                pipe.hincrby(f"{_P}job:{job_id}", "units_total", total)
            if done:
                pipe.hincrby(f"{_P}job:{job_id}", "units_done", done)
            pipe.execute()

    def tile_done(self, job_id: str, item: int, tile: str, *, total: int = 0, planned: int = 0) -> bool:
        """Count a finished tile once, however often its task ran; with it, in the same write,
        add `total` to the job's units and `planned` to its planned items (an item's plan:
        counted apart, a connection lost between the two writes left the job's total at its
        estimate for good, seen as units done 4 of 12 on a job that had succeeded)."""
        return bool(self._tile_done(keys=[f"{_P}job:{job_id}", f"{_P}job:{job_id}:tiles:{item}"],
                                    args=[tile, total, planned]))

    def item_done(self, job_id: str, item: int, verdict: str | None = None, *, failed: bool = False) -> int:
        """Mark an item finished (once), counting its `verdict` (pass, fail, uncertain) if it
        has one, and it among the failed items if it `failed`; returns how many items of the
        job are finished."""
        return int(self._item_done(keys=[f"{_P}job:{job_id}", f"{_P}job:{job_id}:done"],
                                   args=[item, verdict or "", "1" if failed else "0"]))

    # -- video frames -----------------------------------------------------------------------
    def claim_frames(self, job_id: str, item: int, count: int) -> int:
        """Record that the item measures `count` frames; the job's total over its items."""
        key = f"{_P}job:{job_id}:frames"
        with self._r.pipeline() as pipe:
            pipe.hset(key, str(item), count)  # a re-run sets the same count again
            pipe.hvals(key)
            return sum(int(v) for v in pipe.execute()[1])

    def release_frames(self, job_id: str, item: int) -> None:
        """The item will not measure its frames after all (it failed): free its share."""
        self._r.hdel(f"{_P}job:{job_id}:frames", str(item))

    def claim_split_part(self, job_id: str, item: int, part: int) -> bool:
        """True once per part of a video's split: the one task that hands the rest on to it."""
        return bool(self._r.hsetnx(f"{_P}job:{job_id}", f"split:{item}:{part}", 1))

    def put_frame(self, job_id: str, item: int, frame: FrameRecord) -> None:
        self._r.hset(f"{_P}job:{job_id}", f"frame:{item}:{frame.index}", frame.model_dump_json())

    def get_frames(self, job_id: str, item: int, indices: builtins.list[int]) -> dict[int, FrameRecord]:
        """The recorded frames among `indices` (a frame not recorded yet is left out)."""
        values = self._r.hmget(f"{_P}job:{job_id}", [f"frame:{item}:{n}" for n in indices])
        return {n: FrameRecord.model_validate_json(v) for n, v in zip(indices, values, strict=True) if v}

    def frame_done(self, job_id: str, item: int, frame: int) -> int:
        """Count a finished frame once (a progress unit); how many of the item's are finished."""
        self.tile_done(job_id, item, f"frame-{frame}")
        with self._r.pipeline() as pipe:
            pipe.sadd(f"{_P}job:{job_id}:frames:{item}", frame)
            pipe.scard(f"{_P}job:{job_id}:frames:{item}")
            return int(pipe.execute()[1])

    # -- what the watchdog asks --------------------------------------------------------------
    def unfinished(self) -> builtins.list[tuple[str, int, float]]:
        """(id, units_done, created at in s since the epoch) of every queued and running job."""
        ids = [*self._r.zrange(f"{_P}state:queued", 0, -1), *self._r.zrange(f"{_P}state:running", 0, -1)]
        with self._r.pipeline(transaction=False) as pipe:
            for job_id in ids:
                pipe.hmget(f"{_P}job:{job_id}", "units_done", "score")
            rows = pipe.execute()
        return [(job_id, int(done or 0), float(score or 0) / 1e6)
                for job_id, (done, score) in zip(ids, rows, strict=True)]

    def done_items(self, job_id: str) -> set[int]:
        """The indices of the job's finished items (`item_done`)."""
        return {int(i) for i in self._r.smembers(f"{_P}job:{job_id}:done")}

    def claimed_items(self, job_id: str, n_items: int) -> int:
        """How many items have been started (claimed through `next_item`)."""
        return min(int(self._r.get(f"{_P}job:{job_id}:next") or 0), n_items)

    def get_watch(self, job_id: str) -> dict[str, str]:
        """What the watchdog noted of the job ({} if nothing): units, since, restarts."""
        found = self._r.hgetall(f"{_P}watch:{job_id}")
        return {_text(k): _text(v) for k, v in found.items()}

    def set_watch(self, job_id: str, *, since: float, units: int | None = None,
                  restarts: int | None = None, ttl_s: int | None = None) -> None:
        """Note what the watchdog saw at `since` (s); `ttl_s` lets the note expire."""
        key = f"{_P}watch:{job_id}"
        mapping: dict[FieldT, EncodableT] = {"since": since}
        if units is not None:
            mapping["units"] = units
        if restarts is not None:
            mapping["restarts"] = restarts
        self._r.hset(key, mapping=mapping)
        if ttl_s is not None:
            self._r.expire(key, ttl_s)

    def take_watchdog_lock(self, holder: str, ttl_s: int) -> bool:
        """Take the sweep of this interval (SET NX with expiry); False if another holds it."""
        return bool(self._r.set(WATCHDOG_LOCK_KEY, holder, nx=True, ex=max(1, ttl_s)))

    def server_time(self) -> float:
        """Redis's clock (s since the epoch): one clock for every worker on every host."""
        seconds, micros = self._r.time()
        return seconds + micros / 1e6

    def count_by_state(self) -> dict[str, int]:
        with self._r.pipeline() as pipe:
            for s in State:
                pipe.zcard(f"{_P}state:{s.value}")
            return dict(zip([s.value for s in State], pipe.execute(), strict=True))

def _text(value: bytes | str) -> str:
    """A reply as text (the store's clients decode replies; a raw client's bytes are UTF-8)."""
    return value if isinstance(value, str) else value.decode()


def _job_fields(values: list[str | None]) -> dict[str, str]:
    """The job hash's own fields (_JOB_FIELDS) from an HMGET of them, the missing left out."""
    return {k: v for k, v in zip(_JOB_FIELDS, values, strict=True) if v is not None}


def _attach_frames(items: dict[int, ItemRecord], fields: dict[str, str]) -> None:
    """Add to `items` (index -> record) their frames among `fields` (``frame:{i}:{n}``), in order."""
    frames = sorted((int(k.split(":")[1]), int(k.split(":")[2]), v) for k, v in fields.items()
                    if k.startswith("frame:"))
    for i, _, value in frames:
        if i in items:
            items[i].frames.append(FrameRecord.model_validate_json(value))


def _idem_key(tenant: str, idempotency_key: str) -> str:
    return f"{_P}idem:{tenant}:{hashlib.sha256(idempotency_key.encode()).hexdigest()}"


def _job(fields: dict[str, str], indices: range | None = None) -> JobRecord:
    """A job record from its hash's fields, with the items at `indices` (default: all)."""
    if indices is None:
        indices = range(int(fields["n_items"]))
    items = {i: ItemRecord.model_validate_json(fields[f"item:{i}"]) for i in indices}
    _attach_frames(items, fields)
    job = JobRecord.model_validate({**json.loads(fields["doc"]), "items": list(items.values())})
    job.state = State(fields["state"])
    for name in ("started_at", "finished_at"):
        if fields.get(name):
            setattr(job, name, datetime.fromisoformat(fields[name]))
    job.error = fields.get("error") or None
    job.items_done = int(fields.get("items_done", 0))
    job.items_failed = int(fields.get("items_failed", 0))
    job.verdicts = {name.split(":")[1]: int(fields.get(name, 0)) for name in _VERDICT_FIELDS}
    counts = (int(fields.get("units_done", 0)), int(fields.get("units_total", 1)),
              int(fields.get("items_planned", 0)))
    n_items = int(fields["n_items"])
    if job.state == State.cancelled:
        # Progress counts the work finished when the job was cancelled (a task in flight then
        # may still count its unit before it stops), and what had not finished never will: its
        # items and frames read as cancelled (the worker's tasks stop at their next step).
        if fields.get("units_at_cancel"):
            at_cancel = [int(n) for n in fields["units_at_cancel"].split("/")]
            counts = (at_cancel[0], at_cancel[1], at_cancel[2] if len(at_cancel) > 2 else 0)
        job.progress = min(100, int(100 * progress(*counts, n_items)))
        for item in job.items:
            _cancel_unfinished(item)
            for frame in item.frames:
                _cancel_unfinished(frame)
    else:
        job.progress = 100 if job.state in FINAL_STATES else min(99, int(100 * progress(*counts, n_items)))
    return job


def progress(done: int, total: int, planned: int, n_items: int) -> float:
    """Finished work over all work, 0-1, from the job's unit counts.

    An item's work is known once it is planned (1 plan + its tiles or frames + 1 complete; a
    batch item scanned whole is 2); until then `total` holds UNITS_PER_ITEM_ESTIMATE for it.
    With some items planned, an unplanned one is taken to be as big as the planned ones are on
    average: a batch of whole items (2 units each) must not read as if each item still to come
    were 10 (4 of 40 done read 2 %, 10 of 12 read 50 %). Before any item is planned nothing is
    done and the estimate stands.
    """
    if 0 < planned < n_items:
        planned_units = total - UNITS_PER_ITEM_ESTIMATE * (n_items - planned)
        return done / max(planned_units * n_items / planned, 1)
    return done / max(total, 1)


def _cancel_unfinished(record: ItemRecord | FrameRecord) -> None:
    if record.state in (State.queued, State.running):
        record.state = State.cancelled

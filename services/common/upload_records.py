"""Upload records in Redis, beside the jobs (JobStore inherits these methods).

* ``upload:{id}`` hash: tenant, object key, size, file name, made at, and ``probe``: what the
  API found the file to be when it was stored (JSON: kind "image" or "video", format, width and
  height as the engine sees them, a video's frame_count, fps and codec; see `prism_api.probe`).
* ``uploads`` sorted set: upload id -> when its lifetime counts from (made, or last named by a
  submitted job), s since the epoch: the sweep deletes those past ``upload_ttl_s``.
* ``upload:{id}:extract:{n}`` (expiring): frame n of that video was asked of a worker;
  ``upload:{id}:points:{name}`` (expiring): that point search was (`claim_points`).
* ``tenant:{t}:upload-sha256:{hex}:{name}``: the tenant's upload of that content under that
  name, so the same file sent again is answered with the upload it already has (the name is
  part of it: errors about an upload quote the name the client gave it).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any, cast

import redis
from redis.typing import EncodableT, FieldT

__all__ = ["UploadRecords", "upload_probe"]

_P = "prism:"


def upload_probe(record: Mapping[str, str] | None) -> dict[str, Any] | None:
    """The probe recorded with an upload (`get_upload`'s record), or None (none recorded: an
    upload stored before uploads were probed)."""
    text = record.get("probe") if record else None
    if not text:
        return None
    try:
        found = json.loads(text)
    except ValueError:
        return None
    return found if isinstance(found, dict) else None
_UPLOADS = f"{_P}uploads"


def _sha_key(tenant: str, sha256: str, name: str) -> str:
    return f"{_P}tenant:{tenant}:upload-sha256:{sha256}:{hashlib.sha256(name.encode()).hexdigest()[:16]}"


class UploadRecords:
    """The upload half of the job store: methods over the store's Redis client, `_r`, which
    decodes replies (as JobStore's must): they are cast to str here."""

    _r: redis.Redis

    def put_upload(self, upload_id: str, *, tenant: str, key: str, size: int, name: str,
                   probe: Mapping[str, Any] | None = None, sha256: str | None = None) -> None:
        now = datetime.now(UTC)
        fields: dict[FieldT, EncodableT] = {"tenant": tenant, "key": key, "size": size, "name": name,
                                        "created_at": now.isoformat()}
        if probe is not None:
            fields["probe"] = json.dumps(dict(probe))
        if sha256 is not None:
            fields["sha256"] = sha256
        with self._r.pipeline() as pipe:
            pipe.hset(f"{_P}upload:{upload_id}", mapping=fields)
            if sha256 is not None:
                pipe.set(_sha_key(tenant, sha256, name), upload_id)
            pipe.zadd(_UPLOADS, {upload_id: now.timestamp()})  # for their expiry
            pipe.execute()

    def touch_uploads(self, upload_ids: set[str]) -> None:
        """Count these uploads' age from now (a job reads them: they must outlive it)."""
        if upload_ids:
            now = datetime.now(UTC).timestamp()
            self._r.zadd(_UPLOADS, dict.fromkeys(upload_ids, now), gt=True)

    def index_old_uploads(self) -> int:
        """List for expiry the uploads made before uploads were listed (at their made time);
        how many were added. Safe to run again: listed ones are left as they are."""
        added = 0
        for key in self._r.scan_iter(match=f"{_P}upload:*", count=1000):
            upload_id = key.removeprefix(f"{_P}upload:")
            if ":" in upload_id:  # an extraction claim, not an upload
                continue
            made = cast("str | None", self._r.hget(key, "created_at"))
            if made is not None:
                stamp = datetime.fromisoformat(made).timestamp()
                added += cast(int, self._r.zadd(_UPLOADS, {upload_id: stamp}, nx=True))
        return added

    def uploads_before(self, when: float, limit: int = 500) -> list[str]:
        """Ids of up to `limit` uploads made before `when` (s since the epoch), oldest first."""
        return cast("list[str]", self._r.zrangebyscore(_UPLOADS, "-inf", f"({when!r}", start=0, num=limit))

    def find_upload(self, tenant: str, sha256: str, name: str) -> tuple[str, dict[str, str]] | None:
        """The tenant's upload of this content (SHA-256) under this name (id and record), if
        it is still kept."""
        upload_id = cast("str | None", self._r.get(_sha_key(tenant, sha256, name)))
        if not upload_id:
            return None
        record = self.get_upload(upload_id)
        if record is None or record.get("tenant") != tenant or record.get("sha256") != sha256:
            return None
        return upload_id, record

    def delete_upload(self, upload_id: str) -> None:
        tenant, sha256, name = cast("list[str | None]", self._r.hmget(f"{_P}upload:{upload_id}",
                                                                       ["tenant", "sha256", "name"]))
        if tenant and sha256 and self._r.get(_sha_key(tenant, sha256, name or "")) == upload_id:
            self._r.delete(_sha_key(tenant, sha256, name or ""))
        with self._r.pipeline() as pipe:
            pipe.delete(f"{_P}upload:{upload_id}")
            pipe.zrem(_UPLOADS, upload_id)
            pipe.execute()

    def get_upload(self, upload_id: str) -> dict[str, str] | None:
        return cast("dict[str, str]", self._r.hgetall(f"{_P}upload:{upload_id}")) or None

    def claim_extraction(self, upload_id: str, frame: int, ttl_s: int) -> bool:
        """True for the first asker in `ttl_s` seconds: a page polling for a frame sends its
        extraction once, not at every poll (and again if that task got lost)."""
        return bool(self._r.set(f"{_P}upload:{upload_id}:extract:{frame}", 1, nx=True, ex=ttl_s))

    def claim_points(self, upload_id: str, search: str, ttl_s: int) -> bool:
        """`claim_extraction` for a point search (`search` names it: frame and hint)."""
        return bool(self._r.set(f"{_P}upload:{upload_id}:points:{search}", 1, nx=True, ex=ttl_s))

    def release_points(self, upload_id: str, search: str) -> None:
        """Forget a point search's claim: the next asker sends it again (its task gave up)."""
        self._r.delete(f"{_P}upload:{upload_id}:points:{search}")

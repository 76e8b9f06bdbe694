"""A small typed client of the job API (httpx), the one `prism submit/status/wait/...` use.

For integrators::

    from prism_cli.client import ApiClient

    with ApiClient("http://127.0.0.1:8000", api_key) as api:
        ref = api.upload(Path("box.jpg"))
        job = api.submit({"items": [{"image": ref, "points": [...], "scale": {...}}]})
        job = api.wait(job.id, timeout=600, on_update=lambda j: print(j.progress))
        api.download(job, Path("out"))

        # A station (prism station calibrate's station.json): photos with no points, no scale.
        station = api.create_station(Path("station.json"))
        refs = [api.upload(p) for p in sorted(Path("photos").glob("*.jpg"))]
        job = api.submit({"items": [{"image": r} for r in refs]}, station=station.id)

Answers are the API's own pydantic models (`JobPublic`, `JobList`). A 429 or 503 is retried
after the `Retry-After` the API gives (a few times); a submit always carries an
Idempotency-Key (one is made when none is given), so retrying it cannot make a second job.
"""

from __future__ import annotations

import email.utils
import json
import math
import time
import uuid
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import urlsplit

import httpx
from prism_common.public import JobList, JobPublic, ResultsTable
from prism_common.stations import StationList, StationPublic, VerificationList, VerificationPublic

from prismcore.spec import FILE_NAMES, frame_folder

from .errors import ApiError, WaitTimeoutError

__all__ = ["FINAL_STATES", "ApiClient", "ApiError", "JobList", "StationPublic", "WaitTimeoutError",
           "format_eta", "remaining_s"]

FINAL_STATES = frozenset({"succeeded", "completed_with_failures", "failed", "cancelled"})
_RETRY_STATUSES = frozenset({429, 503})


def remaining_s(job: JobPublic, now: datetime | None = None) -> float | None:
    """Seconds left, estimated from the progress made since the job started; None until the
    job has made some progress (or after it ended)."""
    if job.state in FINAL_STATES or job.started_at is None or job.progress <= 0:
        return None
    elapsed = ((now or datetime.now(UTC)) - job.started_at).total_seconds()
    return max(0.0, elapsed * (100 - job.progress) / job.progress)


def _retry_after_s(response: httpx.Response, default: float) -> float:
    value = response.headers.get("Retry-After")
    if value is None:
        return default
    try:
        return max(0.0, float(value))
    except ValueError:  # an HTTP date
        when = email.utils.parsedate_to_datetime(value)
        return max(0.0, (when - datetime.now(UTC)).total_seconds())


def _message(response: httpx.Response) -> tuple[str, dict[str, Any]]:
    """One line from an error answer: the problem's detail (and its field errors), else text."""
    try:
        body = response.json()
    except ValueError:
        return " ".join(response.text.split())[:300] or response.reason_phrase, {}
    if not isinstance(body, dict):
        return str(body)[:300], {}
    detail = body.get("detail")
    if isinstance(detail, list):  # FastAPI's own shape, from an older API
        detail = "; ".join(str(e.get("msg", e)) if isinstance(e, dict) else str(e) for e in detail)
    text = str(detail or body.get("title") or response.reason_phrase)
    errors = body.get("errors")
    if isinstance(errors, list) and errors:
        named = [f"{e.get('pointer') or e.get('parameter') or e.get('header') or '?'}: {e.get('detail')}"
                 for e in errors[:5] if isinstance(e, dict)]
        if named and not all(n.split(": ", 1)[1] in text for n in named):
            text += " (" + "; ".join(named) + ")"
    return " ".join(text.split()), body


def _file_name(kind: str, url: str) -> str:
    """The file an output is saved as: FILE_NAMES' name, the overlay with its stored suffix
    (overlay.jpg; overlay.png for a job from before the overlay was a JPEG)."""
    name = FILE_NAMES.get(kind, kind)
    if kind in ("overlay", "overlay_side"):
        suffix = PurePosixPath(urlsplit(url).path).suffix
        if suffix in (".jpg", ".png", ".webp"):
            name = PurePosixPath(name).stem + suffix
    return name


class ApiClient:
    """Talks to one API with one key.

    Seams for tests: `transport` (an httpx transport), `sleep` (the waits between polls and
    before retries) and `retries` (how often a 429/503 is retried).
    """

    def __init__(self, base_url: str, api_key: str, *, timeout: float = 30.0,
                 transport: httpx.BaseTransport | None = None, retries: int = 5,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self._http = httpx.Client(base_url=base_url.rstrip("/"), timeout=timeout,
                                  headers={"X-API-Key": api_key}, transport=transport)
        self._retries, self._sleep = retries, sleep
        self._uploaded: dict[tuple[str, int, int], str] = {}

    def __enter__(self) -> ApiClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    def _call(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        for attempt in range(self._retries + 1):
            try:
                response = self._http.request(method, url, **kwargs)
            except httpx.HTTPError as exc:
                raise ApiError(f"cannot reach the API at {self._http.base_url}: {exc}") from None
            if response.status_code in _RETRY_STATUSES and attempt < self._retries:
                self._sleep(min(300.0, _retry_after_s(response, default=2.0 ** attempt)))
                self._rewind(kwargs)
                continue
            if response.status_code >= 400:
                text, problem = _message(response)
                raise ApiError(f"HTTP {response.status_code}: {text}", status=response.status_code,
                               problem=problem)
            return response
        raise AssertionError("unreachable")

    @staticmethod
    def _rewind(kwargs: dict[str, Any]) -> None:
        files = kwargs.get("files") or {}
        # httpx takes files as a mapping or as (field, file) pairs (a field given more than once,
        # as a station's calibration photos are).
        for _, value in files.items() if isinstance(files, dict) else files:
            handle = value[1] if isinstance(value, tuple) else value
            if hasattr(handle, "seek"):
                handle.seek(0)

    # -- uploads ------------------------------------------------------------------------------
    def upload(self, path: Path) -> str:
        """Upload a local file; returns its reference (``upload:ID``). A file this client
        already uploaded (same path, size and modification time) is not sent again."""
        stat = path.stat()
        key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
        if key not in self._uploaded:
            with path.open("rb") as fh:
                response = self._call("POST", "/v1/uploads", files={"file": (path.name, fh)})
            self._uploaded[key] = response.json()["reference"]
        return self._uploaded[key]

    # -- stations -----------------------------------------------------------------------------
    def create_station(self, station: Path | dict[str, Any], *, name: str | None = None) -> StationPublic:
        """Store a station (station.json's path, or its parsed document) as one of the key's
        stations; its summary (`.id` names it in items)."""
        content = station.read_bytes() if isinstance(station, Path) else json.dumps(station).encode()
        response = self._call("POST", "/v1/stations", content=content, params={"name": name} if name else {},
                              headers={"Content-Type": "application/json"})
        return StationPublic.model_validate(response.json())

    def calibrate_station(self, board: Path, plane: Path, photos: list[Path] | None = None, *,
                          camera: Path | None = None, plate: Path | None = None,
                          name: str | None = None) -> StationPublic:
        """Have the service calibrate a station from its photos (as `prism station calibrate`
        takes them: board.json, the plane photo, the board in several poses unless `camera` is
        given, the empty support) and store it; its summary."""
        named = [("board", board), ("plane", plane), *(("calibration", p) for p in photos or []),
                 *([("camera", camera)] if camera else []), *([("plate", plate)] if plate else [])]
        files = [(field, (path.name, path.read_bytes())) for field, path in named]
        response = self._call("POST", "/v1/stations", files=files, params={"name": name} if name else {})
        return StationPublic.model_validate(response.json())

    def verify_station(self, station_id: str, photos: list[Path], reference: str | tuple[float, float, float],
                       tolerance: float | None = None) -> VerificationPublic:
        """Verify the station with a reference part (as `prism station verify` does): its photos in
        5 or more placements, its size W,D,H mm (width >= depth, then height), optionally T of +-T.
        The verification, verified or not (`.verified`); the service stores it with the station."""
        size = reference if isinstance(reference, str) else ",".join(f"{v:g}" for v in reference)
        files = [("photo", (path.name, path.read_bytes())) for path in photos]
        data = {"reference": size, **({"tolerance": f"{tolerance:g}"} if tolerance is not None else {})}
        response = self._call("POST", f"/v1/stations/{station_id}/verifications", files=files, data=data)
        return VerificationPublic.model_validate(response.json())

    def station_verifications(self, station_id: str) -> list[VerificationPublic]:
        """The station's verifications, newest first."""
        found = self._call("GET", f"/v1/stations/{station_id}/verifications").json()
        return VerificationList.model_validate(found).verifications

    def station(self, station_id: str) -> StationPublic:
        return StationPublic.model_validate(self._call("GET", f"/v1/stations/{station_id}").json())

    def stations(self) -> list[StationPublic]:
        """The key's stations, newest first."""
        return StationList.model_validate(self._call("GET", "/v1/stations").json()).stations

    def station_document(self, station_id: str) -> dict[str, Any]:
        """The stored station.json (its plate included), as `prism scan --station` reads it."""
        found: dict[str, Any] = self._call("GET", f"/v1/stations/{station_id}/station.json").json()
        return found

    def delete_station(self, station_id: str) -> None:
        self._call("DELETE", f"/v1/stations/{station_id}")

    # -- jobs ---------------------------------------------------------------------------------
    def submit(self, body: dict[str, Any], *, idempotency_key: str | None = None,
               station: str | None = None) -> JobPublic:
        """Submit a job (`JobCreate`'s shape); 202's job. Retried safely: the same key each time.
        `station`: every item that names none is measured on this station (no points, no scale)."""
        if station is not None:
            body = {**body, "items": [item if "station" in item else {**item, "station": station}
                                      for item in body["items"]]}
        key = idempotency_key or f"prism-client-{uuid.uuid4().hex}"
        response = self._call("POST", "/v1/jobs", json=body, headers={"Idempotency-Key": key})
        return JobPublic.model_validate(response.json())

    def job(self, job_id: str, *, items: bool = True) -> JobPublic:
        """The job; without its items (state and progress only) when `items` is False."""
        params = {} if items else {"item_limit": 0}
        return JobPublic.model_validate(self._call("GET", f"/v1/jobs/{job_id}", params=params).json())

    def jobs(self, *, state: str | None = None, limit: int = 50, cursor: str | None = None) -> JobList:
        """One page of the key's jobs, newest first, without their items."""
        params: dict[str, Any] = {"limit": limit, "items": "false"}
        if state:
            params["state"] = state
        if cursor:
            params["cursor"] = cursor
        return JobList.model_validate(self._call("GET", "/v1/jobs", params=params).json())

    def iter_jobs(self, *, state: str | None = None, page: int = 100) -> Iterator[JobPublic]:
        cursor = None
        while True:
            listing = self.jobs(state=state, limit=page, cursor=cursor)
            yield from listing.jobs
            if not listing.next_cursor:
                return
            cursor = listing.next_cursor

    def cancel(self, job_id: str) -> JobPublic:
        return JobPublic.model_validate(self._call("POST", f"/v1/jobs/{job_id}/cancel").json())

    def wait(self, job_id: str, *, timeout: float, poll_s: float = 0.5,
             on_update: Callable[[JobPublic], None] | None = None) -> JobPublic:
        """Poll until the job is final, then return it whole; `WaitTimeoutError` (an ApiError)
        if `timeout` seconds pass first. The polls leave out the items: a big job's would be
        megabytes each time."""
        deadline = time.monotonic() + timeout
        while True:
            job = self.job(job_id, items=False)
            if on_update:
                on_update(job)
            if job.state in FINAL_STATES:
                return self.job(job_id)
            if time.monotonic() > deadline:
                raise WaitTimeoutError(f"job {job_id} still {job.state.value} after {timeout:g} s")
            self._sleep(poll_s)

    # -- outputs ------------------------------------------------------------------------------
    def download(self, job: JobPublic, out_dir: Path) -> list[Path]:
        """Save every item's outputs through their presigned URLs, as out_dir/item-N/FILE (a
        video's frames as out_dir/item-N/frame_000123/FILE, beside its summary.json)."""
        saved = []
        for item in job.items:
            folder = out_dir / f"item-{item.index}"
            places = [(folder, item.downloads)] + [
                (folder / frame_folder(f.index), f.downloads) for f in item.frames]
            for where, downloads in places:
                for kind, url in downloads.items():
                    saved.append(self._save(url, where / _file_name(kind, url)))
        return saved

    def results(self, job_id: str) -> ResultsTable:
        """The job's results table (results.json): a row per item and per video frame."""
        return ResultsTable.model_validate(self._call("GET", f"/v1/jobs/{job_id}/results.json").json())

    def save_results_csv(self, job_id: str, target: Path) -> Path:
        """Save the job's results table as CSV (streamed: a big job's is never held whole)."""
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            with self._http.stream("GET", f"/v1/jobs/{job_id}/results.csv") as response:
                if response.status_code >= 400:
                    response.read()
                    text, problem = _message(response)
                    raise ApiError(f"HTTP {response.status_code}: {text}", status=response.status_code,
                                   problem=problem)
                _write_body(response, target)
        except httpx.HTTPError as exc:
            raise ApiError(f"download of {target.name} failed: {exc}") from None
        return target

    def _save(self, url: str, target: Path) -> Path:
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            with httpx.stream("GET", url, timeout=120) as response:
                response.raise_for_status()
                _write_body(response, target)
        except httpx.HTTPStatusError as exc:  # the store refused the link: its status decides
            raise ApiError(f"download of {target.name} failed: HTTP {exc.response.status_code}",
                           status=exc.response.status_code) from None
        except httpx.HTTPError as exc:
            raise ApiError(f"download of {target.name} failed: {exc}") from None
        return target


def format_eta(seconds: float | None) -> str:
    """'about 3 min left' style text; empty when unknown."""
    if seconds is None or not math.isfinite(seconds):
        return ""
    if seconds < 60:
        return f"about {max(1, round(seconds))} s left"
    if seconds < 3600:
        return f"about {round(seconds / 60)} min left"
    return f"about {seconds / 3600:.1f} h left"


def _write_body(response: httpx.Response, target: Path) -> None:
    """Stream a response's body into `target` a megabyte at a time (never whole in memory)."""
    with target.open("wb") as fh:
        for chunk in response.iter_bytes(1 << 20):
            fh.write(chunk)

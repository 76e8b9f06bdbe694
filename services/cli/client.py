"""A small HTTP client of the job API (httpx), used by `prism submit/status/wait/download`."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import httpx

from prismcore.spec import FILE_NAMES, frame_folder

__all__ = ["FINAL_STATES", "ApiClient", "ApiError"]

FINAL_STATES = frozenset({"succeeded", "failed", "cancelled"})


class ApiError(Exception):
    """The API refused a request (4xx/5xx) or could not be reached; the message says why."""


class ApiClient:
    """Talks to one API with one key. Pass `transport` to test without a network."""

    def __init__(self, base_url: str, api_key: str, *, timeout: float = 30.0,
                 transport: httpx.BaseTransport | None = None) -> None:
        self._http = httpx.Client(base_url=base_url.rstrip("/"), timeout=timeout,
                                  headers={"X-API-Key": api_key}, transport=transport)

    def close(self) -> None:
        self._http.close()

    def _call(self, method: str, url: str, **kwargs) -> httpx.Response:
        try:
            response = self._http.request(method, url, **kwargs)
        except httpx.HTTPError as exc:
            raise ApiError(f"cannot reach the API at {self._http.base_url}: {exc}") from None
        if response.status_code >= 400:
            try:
                detail = response.json().get("detail", response.text)
            except ValueError:
                detail = response.text
            raise ApiError(f"HTTP {response.status_code}: {detail}")
        return response

    def upload(self, path: Path) -> str:
        """Upload a local file; returns its reference (``upload:ID``)."""
        with path.open("rb") as fh:
            response = self._call("POST", "/v1/uploads", files={"file": (path.name, fh)})
        return response.json()["reference"]

    def submit(self, body: dict, *, idempotency_key: str | None = None) -> dict:
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        return self._call("POST", "/v1/jobs", json=body, headers=headers).json()

    def job(self, job_id: str, *, items: bool = True) -> dict:
        """The job; without its items (state and progress only) when `items` is False."""
        params = {} if items else {"item_limit": 0}
        return self._call("GET", f"/v1/jobs/{job_id}", params=params).json()

    def cancel(self, job_id: str) -> dict:
        return self._call("POST", f"/v1/jobs/{job_id}/cancel").json()

    def wait(self, job_id: str, *, timeout: float, poll_s: float = 0.5,
             on_update: Callable[[dict], None] | None = None) -> dict:
        """Poll until the job is final, then return it whole; ApiError if `timeout` seconds pass
        first. The polls leave out the items: a big job's would be megabytes each time."""
        deadline = time.monotonic() + timeout
        while True:
            job = self.job(job_id, items=False)
            if on_update:
                on_update(job)
            if job["state"] in FINAL_STATES:
                return self.job(job_id)
            if time.monotonic() > deadline:
                raise ApiError(f"job {job_id} still {job['state']} after {timeout:g} s")
            time.sleep(poll_s)

    def download(self, job: dict, out_dir: Path) -> list[Path]:
        """Save every item's outputs through their presigned URLs, as out_dir/item-N/FILE (a
        video's frames as out_dir/item-N/frame_000123/FILE, beside its summary.json)."""
        saved = []
        for item in job["items"]:
            folder = out_dir / f"item-{item['index']}"
            places = [(folder, item.get("downloads") or {})] + [
                (folder / frame_folder(f["index"]), f.get("downloads") or {})
                for f in item.get("frames") or []]
            for where, downloads in places:
                for kind, url in downloads.items():
                    saved.append(self._save(url, where / FILE_NAMES[kind]))
        return saved

    def _save(self, url: str, target: Path) -> Path:
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            with httpx.stream("GET", url, timeout=120) as response:
                response.raise_for_status()
                with target.open("wb") as fh:
                    for chunk in response.iter_bytes(1 << 20):
                        fh.write(chunk)
        except httpx.HTTPError as exc:
            raise ApiError(f"download of {target.name} failed: {exc}") from None
        return target

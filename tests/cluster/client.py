"""The client host's side: an HTTP client that rides out restarts (retrying with the same
Idempotency-Key), a webhook receiver, a steady stream of submitted jobs, and the audit that
counts lost and duplicated jobs from independent sources (the API, the webhooks, the object
store, the engine run in this process).
"""

from __future__ import annotations

import io
import json
import threading
import time
import uuid
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import cv2
import httpx
import numpy as np
from prism_common.settings import Settings
from prism_common.storage import ObjectStore

from prismcore import ScanSpec, run_scan
from prismcore.outputs.writers import write_format
from prismcore.report import report_dict
from prismsynth import Box, Scene, render_oblique_view

from .cluster import API_KEY, BUCKET, S3_KEY_ID, S3_SECRET, WEBHOOK_SECRET

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
FINAL = ("succeeded", "failed", "cancelled")
BOX = Box(120.0, 80.0, 60.0)


def scene(seed: int) -> Scene:
    """A 160x128 render: a scan in milliseconds, so many jobs fit in a fault's window."""
    return render_oblique_view(BOX, image_size=(160, 128), focal_px=175.0, seed=seed)


def png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    assert ok
    return data.tobytes()


def item(reference: str, s: Scene) -> dict:
    # CSV and PLY, and the cloud's spacing, named (the service's defaults, but a deployment may
    # set others): the oracle compares the PLY, the engine's exact cloud for this very spec.
    return {"image": reference, "points": [list(map(round, s.points[n])) for n in NAMES],
            "focal_px": s.focal_px, "scale": {"kind": "pinhole", "distance_mm": s.distance_mm},
            "formats": ["csv", "ply"], "spacing_mm": 1.0}


class Api:
    def __init__(self, base_url: str) -> None:
        self.http = httpx.Client(base_url=base_url, timeout=15, headers={"X-API-Key": API_KEY})

    def call(self, method: str, path: str, *, patience: float = 120, **kwargs) -> httpx.Response:
        """Retries connection errors, 503s and 429s for `patience` s, after the Retry-After the
        API gives, as a client should (a submit carries its Idempotency-Key, so a retry cannot
        make a second job)."""
        deadline = time.monotonic() + patience
        while True:
            wait = 0.3
            try:
                r = self.http.request(method, path, **kwargs)
                if r.status_code not in (429, 503):
                    return r
                after = r.headers.get("Retry-After", "")
                wait = max(wait, float(after) if after.isdigit() else 1.0)  # our API gives seconds
            except httpx.TransportError:
                pass
            if time.monotonic() + wait > deadline:
                raise AssertionError(f"{method} {path}: no answer in {patience} s")
            time.sleep(wait)

    def upload(self, data: bytes) -> str:
        r = self.call("POST", "/v1/uploads", files={"file": ("box.png", data)})
        assert r.status_code in (200, 201), r.text
        return r.json()["reference"]

    def job(self, job_id: str) -> dict:
        r = self.call("GET", f"/v1/jobs/{job_id}")
        assert r.status_code == 200, r.text
        return r.json()

    def listed(self) -> list[dict]:
        jobs, cursor = [], None
        while True:
            params = {"limit": 200, **({"cursor": cursor} if cursor else {})}
            page = self.call("GET", "/v1/jobs", params=params)
            assert page.status_code == 200, page.text
            jobs += page.json()["jobs"]
            if (cursor := page.json()["next_cursor"]) is None:
                return jobs


class Hooks:
    """Receives the webhooks on the client host: per job, every (state, finished_at) told."""

    def __init__(self, address: str, port: int) -> None:
        self.told: dict[str, list[tuple[str, str, str]]] = {}
        lock, told = threading.Lock(), self.told

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                with lock:
                    told.setdefault(body["id"], []).append(
                        (self.headers["webhook-id"], body["state"], body["finished_at"]))
                self.send_response(204)
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer((address, port), Handler)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@dataclass
class Load:
    """Jobs submitted one every `interval` s by a thread until `stop`: `acked` holds each
    acknowledged job's id and when the 202 came."""

    api: Api
    tag: str
    items: list[dict]
    hook_url: str
    interval: float = 0.5
    count: int | None = None  # stop by itself after this many
    acked: dict[str, tuple[str, float]] = field(default_factory=dict)  # reference -> (id, at)
    _stop: threading.Event = field(default_factory=threading.Event)
    error: BaseException | None = None

    def start(self) -> Load:
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        return self

    def _run(self) -> None:
        n = 0
        try:
            while not self._stop.is_set() and (self.count is None or n < self.count):
                reference = f"{self.tag}-{n}"
                r = self.api.call("POST", "/v1/jobs", headers={"Idempotency-Key": uuid.uuid4().hex},
                                  json={"items": self.items, "client_reference": reference,
                                        "webhook_url": self.hook_url})
                assert r.status_code == 202, r.text
                self.acked[reference] = (r.json()["id"], time.monotonic())
                n += 1
                self._stop.wait(self.interval)
        except BaseException as exc:
            self.error = exc

    def stop(self, wait: bool = False) -> None:
        if not wait:
            self._stop.set()
        self.thread.join(180)
        assert not self.thread.is_alive(), f"{self.tag}: a submit hung"
        if self.error is not None:
            raise self.error


def wait_final(api: Api, ids: list[str], timeout: float) -> tuple[dict[str, dict], dict[str, float]]:
    """Each job's final resource and when it was first seen final (monotonic); jobs not
    final by `timeout` are absent."""
    final, seen = {}, {}
    deadline = time.monotonic() + timeout
    while len(final) < len(ids) and time.monotonic() < deadline:
        for job_id in ids:
            if job_id not in final and (job := api.job(job_id))["state"] in FINAL:
                final[job_id], seen[job_id] = job, time.monotonic()
        time.sleep(0.5)
    return final, seen


@dataclass
class Oracle:
    """What each item must give: the engine's own PLY bytes for its spec, run here."""

    ply: list[bytes]
    dimensions: list[list[float]]  # width, height, depth, mm

    @classmethod
    def of(cls, items: list[dict], photos: list[bytes]) -> Oracle:
        plys, dims = [], []
        for spec_dict, photo in zip(items, photos, strict=True):
            spec = ScanSpec.model_validate({**spec_dict, "image": "local.png"})
            image = cv2.cvtColor(cv2.imdecode(np.frombuffer(photo, np.uint8), cv2.IMREAD_COLOR),
                                 cv2.COLOR_BGR2RGB)
            buf = io.BytesIO()
            local = run_scan(spec, image)
            write_format("ply", buf, local.cloud, spec)
            plys.append(buf.getvalue())
            dims.append([report_dict(local.report)["dimensions"][k] for k in ("width", "height", "depth")])
        return cls(plys, dims)


def store_of(endpoint: str) -> ObjectStore:
    return ObjectStore.from_settings(Settings(
        api_keys={"acme": API_KEY}, webhook_secret=WEBHOOK_SECRET, s3_endpoint_url=endpoint,
        s3_bucket=BUCKET, s3_access_key_id=S3_KEY_ID, s3_secret_access_key=S3_SECRET))


@dataclass
class Audit:
    jobs: int
    lost: list[str]
    duplicated: list[str]
    failed: list[str]
    problems: list[str]


def audit(api: Api, load: Load, final: dict[str, dict], hooks: Hooks, objects: ObjectStore,
          oracle: Oracle, redis_client) -> Audit:
    """Lost: acknowledged and not final, or final without its outputs. Duplicated: a reference
    that made two jobs, a job told final twice differently (webhooks, job.json, the API), an
    output that differs from the engine's, a unit of work counted twice."""
    lost, duplicated, failed, problems = [], [], [], []
    per_reference: dict[str, int] = {}
    for job in api.listed():
        if (ref := job["client_reference"] or "").startswith(load.tag + "-"):
            per_reference[ref] = per_reference.get(ref, 0) + 1
    for reference, (job_id, _) in load.acked.items():
        if per_reference.get(reference, 0) > 1:
            duplicated.append(job_id)
            problems.append(f"{reference}: {per_reference[reference]} jobs")
        job = final.get(job_id)
        if job is None:
            lost.append(job_id)
            problems.append(f"{job_id}: not final")
            continue
        if job["state"] != "succeeded" or any(i["state"] != "succeeded" for i in job["items"]):
            failed.append(job_id)
            problems.append(f"{job_id}: {job['state']} {job['error']} "
                            f"{[i['error'] for i in job['items'] if i['error']]}")
            continue
        endings = {(state, at) for _, state, at in hooks.told.get(job_id, [])}
        again = api.job(job_id)
        try:
            stored = json.loads(objects.get_bytes(f"jobs/{job_id}/job.json"))
        except Exception as exc:
            lost.append(job_id)
            problems.append(f"{job_id}: job.json unreadable: {exc}")
            continue
        told = {(job["state"], job["finished_at"]), (again["state"], again["finished_at"])}
        stored_end = (stored["state"], stored["finished_at"])
        units = redis_client.hmget(f"prism:job:{job_id}", "units_total", "units_done")
        outputs_differ = False
        for index, it in enumerate(job["items"]):
            r = httpx.get(it["downloads"]["ply"], timeout=30)
            if r.status_code != 200:
                lost.append(job_id)
                problems.append(f"{job_id} item {index}: ply answered {r.status_code}")
                break
            outputs_differ |= r.content != oracle.ply[index]
            dims = it["result"]["dimensions"]
            got = [dims["width"], dims["height"], dims["depth"]]
            # The engine's own figures here, and the true box's (the scenes are ones it measures
            # within 1 %).
            if not (np.allclose(got, oracle.dimensions[index], rtol=1e-6)
                    and np.allclose(got, [BOX.width_mm, BOX.height_mm, BOX.depth_mm], rtol=0.02)):
                problems.append(f"{job_id} item {index}: dimensions {got}")
                failed.append(job_id)
        if len(told) > 1 or len(endings) > 1 or (endings and endings != told) or not endings:
            duplicated.append(job_id) if len(endings) > 1 or len(told) > 1 else None
            problems.append(f"{job_id}: API said {told}, webhooks said {endings}")
        if stored_end not in told:
            duplicated.append(job_id)
            problems.append(f"{job_id}: job.json says {stored_end}, the API {told}")
        if outputs_differ:
            duplicated.append(job_id)
            problems.append(f"{job_id}: a PLY differs from the engine's")
        if units[0] is None or int(units[1]) != int(units[0]):
            duplicated.append(job_id)
            problems.append(f"{job_id}: units done/total {units[1]}/{units[0]}")
    return Audit(len(load.acked), sorted(set(lost)), sorted(set(duplicated)), sorted(set(failed)),
                 problems)

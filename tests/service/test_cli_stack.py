"""The `prism` service commands as a user runs them (the installed command, in a subprocess)
against the real stack: the API under uvicorn, a Celery worker, redis-server and SeaweedFS.

Exit codes: 0 the command succeeded, 1 the job waited for failed, was cancelled or completed
with failures (some item failed), 2 bad input
or a request the API refused (one line on stderr). What `--wait` prints: each dimension ± its
sigma, and every warning of the result on the lines after it. `--spec` sends the job file whole
(its client_reference and webhook_url reach the API, and the webhook is delivered).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import cv2
import pytest

from prism_cli.stack import ManagedProcess, start_api, start_worker

from .conftest import API_KEYS
from .servers import service_env

ROOT = Path(__file__).resolve().parents[2]
PRISM = str(Path(sys.executable).parent / "prism")
SAMPLE = ROOT / "samples" / "box.jpg"
TRUE_SIZE = (120.0, 80.0, 60.0)  # the sample's box, mm
FIVE = "395,293 943,331 919,761 943,331 1035,298"
SEVEN = FIVE + " 411,647 1009,660"
_SIZE = r"([\d.]+) ± ([\d.]+)"
_GIVEN = r"([\d.]+) \(given\)()"  # the known edge: its length, no ±
_ITEM = re.compile(rf"item (\d+): succeeded  {_GIVEN} x {_SIZE} x {_SIZE} mm")


class Receiver:
    """Records the webhook POSTs it gets (answers 204)."""

    def __init__(self) -> None:
        self.bodies: list[dict] = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                outer.bodies.append(json.loads(self.rfile.read(int(self.headers["Content-Length"]))))
                self.send_response(204)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture(scope="module")
def api(redis_server, s3_server, tmp_path_factory) -> Iterator[ManagedProcess]:
    tmp = tmp_path_factory.mktemp("cli-stack")
    env = service_env(redis_server.port, s3_server.port, db=8, bucket="t-cli-stack",
                      WEBHOOK_ALLOWED_HOSTS='["127.0.0.1"]', WEBHOOK_ALLOW_HTTP="true",
                      WEBHOOK_ALLOW_PRIVATE="true")
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=2)
    yield api
    worker.stop()
    api.stop()


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    made = Receiver()
    yield made
    made.close()


def prism(api: ManagedProcess, *argv: str, cwd: Path = ROOT,
          timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PRISM_API_URL": f"http://127.0.0.1:{api.port}", "PRISM_API_KEY": API_KEYS["acme"],
           "COLUMNS": "300"}
    return subprocess.run([PRISM, *argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def refused_in_one_line(run: subprocess.CompletedProcess) -> bool:
    return (run.returncode == 2 and run.stderr.count("\n") == 1 and run.stderr.startswith("prism: error: ")
            and "Traceback" not in run.stderr)


def test_a_failed_job_exits_1_and_so_does_waiting_for_it(api, tmp_path: Path):
    # Issue 21's reproduction was a cut JPEG, which is now refused at upload (issue 30): one line.
    cut = tmp_path / "t.jpg"
    cut.write_bytes(SAMPLE.read_bytes()[:2000])
    run = prism(api, "submit", str(cut), "--points", FIVE, "--width-mm", "120", "--wait")
    assert refused_in_one_line(run) and "'t.jpg' is a truncated JPEG (2,000 bytes" in run.stderr, run.stderr
    # A whole PNG whose pixel data is corrupt is stored (its header reads), its item fails.
    photo = cv2.imencode(".png", cv2.imread(str(SAMPLE)))[1].tobytes()
    damaged = tmp_path / "t.png"
    damaged.write_bytes(photo[:200] + bytes(b ^ 0x5A for b in photo[200:400]) + photo[400:])
    run = prism(api, "submit", str(damaged), "--points", FIVE, "--width-mm", "120", "--wait")
    assert run.returncode == 1, run.stdout + run.stderr
    job_id = run.stdout.split()[0]
    assert f"job {job_id}: failed" in run.stdout and "error:" in run.stdout, run.stdout
    assert prism(api, "wait", job_id).returncode == 1
    assert prism(api, "status", job_id).returncode == 0  # telling a failed job's state succeeded


def test_a_job_with_one_failed_item_is_not_succeeded_and_exits_1(api, receiver: Receiver, tmp_path: Path):
    # Issue 37: five items, item 3 a PNG whose pixel data is corrupt (stored, its item fails):
    # the job read `succeeded 100% (5 of 5 items)` and `--wait` exited 0.
    (tmp_path / "box.jpg").symlink_to(SAMPLE)
    photo = cv2.imencode(".png", cv2.imread(str(SAMPLE)))[1].tobytes()
    (tmp_path / "bad.png").write_bytes(photo[:200] + bytes(b ^ 0x5A for b in photo[200:400]) + photo[400:])
    points = [[int(v) for v in p.split(",")] for p in SEVEN.split()]
    items = [{"image": "bad.png" if i == 3 else "box.jpg", "points": points,
              "scale": {"kind": "edge", "edge": "width", "length_mm": 120}} for i in range(5)]
    spec = tmp_path / "job.json"
    spec.write_text(json.dumps({"items": items, "client_reference": "partial", "webhook_url": receiver.url}))
    run = prism(api, "submit", "--spec", str(spec), "--wait")
    assert run.returncode == 1, run.stdout + run.stderr
    job_id = run.stdout.split()[0]
    assert (f"job {job_id}: completed_with_failures 100% (5 of 5 items, 1 failed)" in run.stdout
            and "error: 1 of 5 items failed" in run.stdout), run.stdout
    assert prism(api, "wait", job_id).returncode == 1
    status = json.loads(prism(api, "status", job_id, "--json").stdout)
    assert (status["state"], status["items_done"], status["items_failed"]) == \
        ("completed_with_failures", 5, 1)
    assert [item["state"] for item in status["items"]] == ["succeeded"] * 3 + ["failed", "succeeded"]
    listed = prism(api, "jobs", "--state", "completed_with_failures", "--json")
    assert listed.returncode == 0 and job_id in listed.stdout, listed.stdout + listed.stderr
    deadline = time.monotonic() + 60
    while not receiver.bodies:
        assert time.monotonic() < deadline, "the webhook was not delivered"
        time.sleep(0.2)
    body = receiver.bodies[0]
    assert (body["id"], body["state"], body["items_failed"]) == (job_id, "completed_with_failures", 1)
    # Every item measured is still succeeded, and waiting for it exits 0.
    spec.write_text(json.dumps({"items": items[:2]}))
    run = prism(api, "submit", "--spec", str(spec), "--wait")
    assert run.returncode == 0 and ": succeeded 100% (2 of 2 items)" in run.stdout, run.stdout + run.stderr


def test_a_cancelled_job_exits_1_when_waited_for(api):
    run = prism(api, "submit", "--spec", "samples/batch.json")  # 40 items
    assert run.returncode == 0, run.stderr
    job_id = run.stdout.strip()
    cancel = prism(api, "cancel", job_id)
    assert cancel.returncode == 0 and f"job {job_id}: cancelled" in cancel.stdout, cancel.stdout
    assert prism(api, "wait", job_id).returncode == 1


def test_a_measurement_prints_each_sigma_and_every_warning_after_its_line(api, tmp_path: Path):
    # Seven points: the perspective is fitted, the sample's true size lies within the printed ±.
    run = prism(api, "submit", "samples/box.jpg", "--points", SEVEN, "--width-mm", "120", "--wait")
    assert run.returncode == 0, run.stdout + run.stderr
    found = _ITEM.search(run.stdout)
    assert found, run.stdout
    values = [float(v or 0.0) for v in found.groups()[1:]]
    for (value, sigma), true in zip(zip(values[::2], values[1::2], strict=True), TRUE_SIZE, strict=True):
        assert abs(value - true) <= sigma + 0.01, run.stdout  # 0.01: the printed rounding
    # Five points: the square-on model's depth is far off, and the warning saying so is printed
    # on the lines after the item's, not only in report.json.
    run = prism(api, "submit", "samples/box.jpg", "--points", FIVE, "--width-mm", "120", "--wait")
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("  item 0: succeeded"))
    assert " ± " in lines[at], run.stdout
    warnings = [line for line in lines[at + 1:] if line.startswith("    warning: ")]
    assert any("81%" in w and "P6 and P7" in w for w in warnings), run.stdout
    job_id = lines[0].strip()
    report = json.loads((_downloaded(api, job_id, tmp_path) / "item-0" / "report.json").read_text())
    assert [f"    warning: {w}" for w in report["warnings"]] == warnings  # every one of them


def _downloaded(api: ManagedProcess, job_id: str, out: Path) -> Path:
    run = prism(api, "download", job_id, "--out", str(out / job_id))
    assert run.returncode == 0, run.stderr
    assert prism(api, "results", job_id).returncode == 0
    assert prism(api, "jobs", "--limit", "3").returncode == 0
    return out / job_id


def test_submit_spec_sends_the_jobs_reference_and_webhook(api, receiver: Receiver, tmp_path: Path):
    (tmp_path / "box.jpg").symlink_to(SAMPLE)
    job = json.loads((ROOT / "samples" / "batch.json").read_text())
    spec = tmp_path / "job.json"
    spec.write_text(json.dumps({"items": job["items"][:1], "client_reference": "order-21",
                                "webhook_url": receiver.url}))
    run = prism(api, "submit", "--spec", str(spec), "--wait")
    assert run.returncode == 0, run.stdout + run.stderr
    job_id = run.stdout.split()[0]
    status = json.loads(prism(api, "status", job_id, "--json").stdout)
    assert (status["client_reference"], status["webhook_url"]) == ("order-21", receiver.url)
    deadline = time.monotonic() + 60
    while not receiver.bodies:
        assert time.monotonic() < deadline, "the webhook was not delivered"
        time.sleep(0.2)
    assert receiver.bodies[0]["id"] == job_id and receiver.bodies[0]["client_reference"] == "order-21"
    # A webhook URL the service will not call is refused at submit (it was sent as null before).
    spec.write_text(json.dumps({"items": job["items"][:1], "webhook_url": "ftp://127.0.0.1/hook"}))
    run = prism(api, "submit", "--spec", str(spec))
    assert refused_in_one_line(run) and "HTTP 422" in run.stderr and "/webhook_url" in run.stderr, run.stderr


def test_a_length_out_of_range_is_refused_at_submit(api, tmp_path: Path):
    (tmp_path / "box.jpg").symlink_to(SAMPLE)
    item = {"image": "box.jpg", "points": [[int(v) for v in p.split(",")] for p in SEVEN.split()],
            "scale": {"kind": "edge", "edge": "width", "length_mm": 1e300}}
    spec = tmp_path / "job.json"
    spec.write_text(json.dumps(item))
    run = prism(api, "submit", "--spec", str(spec))  # not checked by the CLI: the API refuses it
    assert refused_in_one_line(run), run.stderr
    assert "HTTP 422" in run.stderr and "/items/0/scale/length_mm" in run.stderr and "1e+300" in run.stderr
    # From flags, the CLI's own spec check refuses it before anything is sent.
    run = prism(api, "submit", "samples/box.jpg", "--points", SEVEN, "--width-mm", "1e300")
    assert refused_in_one_line(run) and "1e+300 mm is out of range" in run.stderr, run.stderr

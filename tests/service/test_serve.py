"""`prism serve`: the whole stack from one command, a job run on it, stopped by Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import psutil
import pytest

from prism_cli.stack import free_port


@pytest.fixture
def served(tmp_path):
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("PRISM_")}
    proc = subprocess.Popen([sys.executable, "-m", "prism_cli", "serve", "--data-dir",
                             str(tmp_path), "--port", str(port), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    yield proc, port, tmp_path
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    proc.stdout.close()


def test_serve_runs_a_job_and_stops_cleanly(served):
    proc, port, data_dir = served
    base = f"http://127.0.0.1:{port}"
    # A deadline to wait within, not a figure to meet: on an idle machine the stack is ready and
    # the sample measured in about 10 s; a loaded CI machine may take several times that.
    started = time.monotonic()
    deadline = started + 240
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{base}/readyz", timeout=2).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        assert proc.poll() is None, proc.stdout.read()
        time.sleep(0.5)
    else:
        raise AssertionError("prism serve did not become ready")
    key = json.loads((data_dir / "credentials.json").read_text())["api_key"]
    headers = {"X-API-Key": key}
    with Path("samples/box.jpg").open("rb") as fh:
        ref = httpx.post(f"{base}/v1/uploads", files={"file": ("box.jpg", fh)},
                         headers=headers).json()["reference"]
    spec = json.loads(Path("samples/job.json").read_text()) | {"image": ref}
    job = httpx.post(f"{base}/v1/jobs", json={"items": [spec]}, headers=headers).json()
    while job["state"] in ("queued", "running") and time.monotonic() < deadline:
        time.sleep(0.5)
        job = httpx.get(f"{base}/v1/jobs/{job['id']}", headers=headers).json()
    assert job["state"] == "succeeded", job
    children = psutil.Process(proc.pid).children(recursive=True)
    assert len(children) >= 4
    proc.send_signal(signal.SIGINT)
    proc.wait(60)
    _, alive = psutil.wait_procs(children, timeout=30)
    assert not alive, alive


def test_serve_exits_1_when_one_of_its_servers_dies(served):
    """A server of the stack that stops (here redis-server, killed) stops prism serve with exit
    code 1 and the log to read; the code was lost on the way out (the command exited 0)."""
    proc, port, _ = served
    deadline = time.monotonic() + 90
    while True:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=2).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.5)
    redis = [p for p in psutil.Process(proc.pid).children(recursive=True) if p.name() == "redis-server"]
    assert len(redis) == 1, redis
    redis[0].kill()
    assert proc.wait(60) == 1
    out = proc.stdout.read()
    assert "redis-server stopped; see" in out and "Traceback" not in out, out

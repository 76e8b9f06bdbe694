"""A client generated from the served OpenAPI document by openapi-python-client (the tool an
integrator would use) uploads the sample photo, submits a job, polls it to the end and reads the
measured box, against the real stack: the API under uvicorn, a Celery worker, Redis, SeaweedFS.

The generator pins httpx and typer releases the service's lock does not hold, so it runs in a
virtualenv of its own, installed from locks/openapi-client.txt (`scripts/lock` makes it, with
hashes) and kept under .venv/ between runs (rebuilt when the lock changes). The generated client
runs in that virtualenv too: its dependencies (httpx, attrs, python-dateutil) are the tool's.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from prism_cli.stack import ManagedProcess, start_api, start_worker

from .conftest import API_KEYS
from .servers import service_env

ROOT = Path(__file__).resolve().parents[2]
LOCK = ROOT / "locks" / "openapi-client.txt"
TOOLS = ROOT / ".venv" / "openapi-client"
SAMPLE = ROOT / "samples" / "box.jpg"
SEVEN = [[395, 293], [943, 331], [919, 761], [943, 331], [1035, 298], [411, 647], [1009, 660]]
TRUE_SIZE = {"width": 120.0, "height": 80.0, "depth": 60.0}  # the sample's box, mm

# The generator's settings: the package's name, and the binary answers (the overlay's JPEG, the
# frame's PNG, the glTF model) read as files, which it otherwise leaves out of the client.
CONFIG = """\
package_name_override: prismcloud_client
content_type_overrides:
  image/png: application/octet-stream
  image/jpeg: application/octet-stream
  model/gltf-binary: application/octet-stream
"""

# What an integrator writes with the generated client: each call a module named after its
# operation id (api/uploads/create_upload.py, api/jobs/create_job.py, get_job.py, results_json.py).
DRIVER = textwrap.dedent("""\
    import json, sys, time
    from prismcloud_client import AuthenticatedClient
    from prismcloud_client.api.jobs import create_job, get_job, results_json
    from prismcloud_client.api.uploads import create_upload
    from prismcloud_client.models import (CreateUploadBody, JobCreate, JobPublic, ScanWithPoints, State,
                                          UploadPublic)
    from prismcloud_client.types import File

    base, key, photo, points = sys.argv[1], sys.argv[2], sys.argv[3], json.loads(sys.argv[4])
    client = AuthenticatedClient(base_url=base, token=key, prefix="", auth_header_name="X-API-Key",
                                 raise_on_unexpected_status=True, timeout=30)
    with client, open(photo, "rb") as f:
        upload = create_upload.sync(client=client, body=CreateUploadBody(
            file=File(payload=f, file_name="box.jpg", mime_type="image/jpeg")))
        assert isinstance(upload, UploadPublic), upload
        item = {"image": upload.reference, "points": points,
                "scale": {"kind": "edge", "edge": "width", "length_mm": 120}}
        job = create_job.sync(client=client, body=JobCreate(items=[ScanWithPoints.from_dict(item)],
                                                            client_reference="generated"))
        assert isinstance(job, JobPublic), job
        polls = 0
        deadline = time.monotonic() + 240
        while job.state in (State.QUEUED, State.RUNNING) and time.monotonic() < deadline:
            time.sleep(0.5)
            job = get_job.sync(job.id, client=client)
            assert isinstance(job, JobPublic), job
            polls += 1
        result = job.items[0].result
        table = results_json.sync_detailed(job.id, client=client)
        print(json.dumps({"state": str(job.state), "polls": polls, "item": str(job.items[0].state),
                          "dimensions": result.dimensions.to_dict() if result else None,
                          "results_rows": len(json.loads(table.content)["rows"])}))
    """)


def _tools() -> Path:
    """The generator's virtualenv, installed from its lock with hashes; one build at a time
    (another test process may be making it), again only when the lock changed."""
    stamp = TOOLS / ".lock.sha256"
    want = hashlib.sha256(LOCK.read_bytes()).hexdigest()
    TOOLS.parent.mkdir(exist_ok=True)
    with open(TOOLS.parent / ".openapi-client.build", "w") as guard:
        fcntl.flock(guard, fcntl.LOCK_EX)
        if not stamp.is_file() or stamp.read_text() != want:
            shutil.rmtree(TOOLS, ignore_errors=True)
            subprocess.run([sys.executable, "-m", "venv", str(TOOLS)], check=True, timeout=120)
            # --isolated: this machine's pip settings (extra indexes, constraints) are not the
            # lock's; the lock names every file by its hash, fetched from PyPI.
            run = subprocess.run([str(TOOLS / "bin" / "python"), "-m", "pip", "install", "--isolated",
                                  "--disable-pip-version-check", "--quiet", "--no-deps",
                                  "--require-hashes", "-r", str(LOCK)],
                                 capture_output=True, text=True, timeout=600)
            assert run.returncode == 0, run.stderr[-3000:]
            stamp.write_text(want)
    return TOOLS


@pytest.fixture(scope="module")
def api(redis_server, s3_server, tmp_path_factory) -> Iterator[ManagedProcess]:
    tmp = tmp_path_factory.mktemp("generated-client")
    env = service_env(redis_server.port, s3_server.port, db=6, bucket="t-generated-client")
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=1)
    yield api
    worker.stop()
    api.stop()


def test_a_generated_client_submits_a_job_polls_it_and_reads_the_result(api, tmp_path: Path) -> None:
    tools = _tools()
    base = f"http://127.0.0.1:{api.port}"
    (tmp_path / "openapi.json").write_text(httpx.get(f"{base}/openapi.json", timeout=30).text)
    (tmp_path / "config.yaml").write_text(CONFIG)
    # The tool's bin first on PATH: it formats what it wrote with its own ruff.
    env = {**os.environ, "PATH": f"{tools / 'bin'}{os.pathsep}{os.environ['PATH']}"}
    gen = subprocess.run([str(tools / "bin" / "openapi-python-client"), "generate", "--path", "openapi.json",
                          "--config", "config.yaml", "--meta", "none"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert gen.returncode == 0, gen.stdout[-3000:] + gen.stderr[-3000:]
    # Every operation and schema was understood: the generator names what it had to leave out.
    assert "Warning" not in gen.stdout + gen.stderr, gen.stdout[-4000:]
    package = tmp_path / "prismcloud_client"
    # The modules read as the operations do (readable operation ids), not as FastAPI's defaults.
    modules = {p.stem for p in (package / "api").rglob("*.py")} - {"__init__"}
    assert {"create_upload", "create_job", "get_job", "list_jobs", "cancel_job", "results_json",
            "results_csv", "create_station", "get_station"} <= modules, sorted(modules)
    assert not any("_v1_" in name for name in modules), sorted(modules)
    # and its models as the schemas are titled (each way of giving an item's points one of them)
    models = {p.stem for p in (package / "models").glob("*.py")}
    assert {"job_create", "job_public", "scan_with_points", "scan_with_views", "scan_on_station",
            "station", "station_camera_model", "camera_model"} <= models, sorted(models)

    (tmp_path / "driver.py").write_text(DRIVER)
    run = subprocess.run([str(tools / "bin" / "python"), "driver.py", base, API_KEYS["acme"], str(SAMPLE),
                          json.dumps(SEVEN)], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    outcome = json.loads(run.stdout.strip().splitlines()[-1])
    assert outcome["state"] == "succeeded" and outcome["item"] == "succeeded", outcome
    assert outcome["polls"] >= 1  # it was polled while queued or running, then read whole
    dims = outcome["dimensions"]
    assert dims["unit"] == "mm"
    assert dims["width"] == pytest.approx(120.0)  # the given edge
    for name in ("height", "depth"):  # the sample's true size, as test_cli_stack holds it
        assert abs(dims[name] - TRUE_SIZE[name]) <= 0.08 * TRUE_SIZE[name], dims
    assert outcome["results_rows"] == 1

"""docker-compose.yml against the Compose specification's JSON Schema, and its topology.

No Docker engine runs here; the integration tests start the same processes (API under
uvicorn, Celery workers, redis-server, SeaweedFS) for real.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

COMPOSE = Path(__file__).parents[1] / "docker-compose.yml"


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


def test_valid_against_compose_spec_schema():
    run = subprocess.run([sys.executable, "-m", "check_jsonschema", "--builtin-schema",
                          "vendor.compose-spec", str(COMPOSE)], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_broken_file_is_caught_by_the_schema_check(tmp_path):
    bad = tmp_path / "docker-compose.yml"
    bad.write_text("services:\n  api:\n    image: x\n    ports: 8000\n    healthcheck: yes\n")
    run = subprocess.run([sys.executable, "-m", "check_jsonschema", "--builtin-schema",
                          "vendor.compose-spec", str(bad)], capture_output=True, text=True)
    assert run.returncode != 0


@pytest.mark.parametrize("service", ["api", "worker", "redis", "s3"])
def test_every_service_has_a_health_check(compose, service):
    assert "test" in compose["services"][service]["healthcheck"]


def test_worker_scales(compose):
    worker = compose["services"]["worker"]
    assert "container_name" not in worker and "ports" not in worker
    assert worker["command"][:3] == ["celery", "-A", "prism_worker.app"]


def test_records_are_durable_and_secrets_required(compose):
    assert "--appendonly" in compose["services"]["redis"]["command"]
    env = compose["services"]["api"]["environment"]
    assert ":?" in env["PRISM_API_KEYS"] and ":?" in env["PRISM_WEBHOOK_SECRET"]
    assert compose["services"]["api"]["depends_on"]["redis"]["condition"] == "service_healthy"

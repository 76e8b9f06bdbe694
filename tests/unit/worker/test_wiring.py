"""The worker's wiring: importing it reads no settings; the Celery app configures itself from
them when first used, with every task registered under its shared name."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from prism_common import queue

_PROBE = """
import json, os
import prism_worker.tasks as tasks
from prism_worker.app import app, worker_context
configured_at_import = app.configured
os.environ.update(PRISM_API_KEYS='{"acme": "k"}', PRISM_WEBHOOK_SECRET="s",
                  PRISM_REDIS_URL="redis://127.0.0.1:9/3", PRISM_VISIBILITY_TIMEOUT_S="100",
                  PRISM_TASK_TIME_LIMIT_S="42")
app.finalize()
print(json.dumps({
    "configured_at_import": configured_at_import,
    "broker": app.conf.broker_url,
    "acks_late": app.conf.task_acks_late,
    "tasks": sorted(name for name in app.tasks if name.startswith("prism.")),
    "backoff_max": tasks.plan_item.retry_backoff_max,
    "soft_limit": app.tasks["prism.plan_item"].soft_time_limit,
    "context_redis_db": worker_context().redis.connection_pool.connection_kwargs["db"],
}))
"""


def test_importing_the_worker_reads_no_settings_and_the_app_configures_itself_on_first_use() -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PRISM_")}
    run = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True,
                         timeout=120, check=False)
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["configured_at_import"] is False
    assert got["broker"] == "redis://127.0.0.1:9/3" and got["acks_late"] is True
    names = {getattr(queue, n) for n in dir(queue) if n.startswith("TASK_")}
    assert set(got["tasks"]) == names
    assert got["backoff_max"] == 50  # half the visibility timeout
    assert got["soft_limit"] == 42.0
    assert got["context_redis_db"] == 3

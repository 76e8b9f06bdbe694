"""Shared fixtures: the session's real redis-server and SeaweedFS (one each for the service and
web tests), and the suite's reliability figures.

Fault, fuzz and soak tests add to `figures` (faults survived, jobs lost, inputs tried, 5xx
seen, ...); the totals are printed at the end of the run, after pytest's own summary.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator

import numpy as np
import pytest
from service.servers import ManagedProcess, start_redis, start_s3

_FIGURES = pytest.StashKey[Counter]()
# Printed in this order (others after them, sorted); each shown even when nothing added to it.
_ORDER = ("faults survived", "jobs submitted", "jobs succeeded", "jobs failed", "jobs lost",
          "jobs duplicated", "inputs tried", "5xx seen")


def pytest_configure(config: pytest.Config) -> None:
    config.stash[_FIGURES] = Counter()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory) -> Iterator[ManagedProcess]:
    server = start_redis(tmp_path_factory.mktemp("redis"))
    yield server
    server.stop()


@pytest.fixture(scope="session")
def s3_server(tmp_path_factory) -> Iterator[ManagedProcess]:
    server = start_s3(tmp_path_factory.mktemp("s3"))
    yield server
    server.stop()


@pytest.fixture(scope="session")
def figures(pytestconfig: pytest.Config) -> Counter:
    """The suite's reliability counters: `figures["inputs tried"] += n`."""
    return pytestconfig.stash[_FIGURES]


def pytest_sessionfinish(session: pytest.Session) -> None:
    # Under pytest-xdist each worker process counts its own tests' figures: it hands them to
    # the controller, which prints the totals.
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        workeroutput["figures"] = dict(session.config.stash[_FIGURES])


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:
    node.config.stash[_FIGURES].update(getattr(node, "workeroutput", {}).get("figures", {}))


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    counts = config.stash.get(_FIGURES, Counter())
    if not counts:
        return  # none of the fault, fuzz or soak tests ran
    terminalreporter.section("reliability figures")
    names = [*_ORDER, *sorted(set(counts) - set(_ORDER))]
    for name in names:
        terminalreporter.write_line(f"{name:>28}: {counts[name]}")

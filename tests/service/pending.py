"""The in-process API against a module's worker environment, and polling its 202 answers: what
the tests of the routes a worker answers for (a video's frames, the point search) share."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from prism_common.settings import Settings, get_settings

from prism_api.main import create_app

from .test_api import TestClient


@contextmanager
def app_client(settings: Settings) -> Iterator[TestClient]:
    """A client of a new app whose settings are `settings` (the worker environment's)."""
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    with TestClient(app) as client:
        yield client


def poll(api: TestClient, path: str, *, working: str, headers: dict, timeout: float):
    """GET until the answer is not 202; every 202 says when to ask again and that the worker is
    `working` ("decoding", "searching")."""
    deadline = time.monotonic() + timeout
    while True:
        r = api.get(path, headers=headers)
        if r.status_code != 202:
            return r
        assert r.headers["Retry-After"] == "1" and working in r.json()["detail"], r.text
        assert time.monotonic() < deadline, f"{path} still 202 after {timeout} s"
        time.sleep(0.1)


def wait_for(condition: Callable[[], bool], timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.1)

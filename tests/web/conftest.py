"""The page in a real headless Chromium, against the real stack: the API under uvicorn (serving
the built page), a Celery worker process, redis-server and SeaweedFS, all on loopback."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Browser, Page, expect, sync_playwright
from service.servers import API_KEYS, service_env

from prism_api.webapp import STATIC_DIR
from prism_cli.stack import ManagedProcess, start_api, start_worker

CHROMIUM = Path("/usr/bin/chromium")  # Debian's; scripts/setup installs it
# No GPU here: WebGL runs on SwiftShader. Nothing may reach outside the machine.
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
VIEWPORT = {"width": 1280, "height": 1000}
# Playwright's expect() waits 5 s by default; much of what the tests expect waits on the stack
# (an upload stored and probed, a video's frame decoded by the worker and polled for at the
# Retry-After of 1 s, a result fetched). With a CI run and 3 CPU burners beside them, 2 cores,
# those steps took up to 1.9 s of the 5 (test_page_video.py): 2.6x more load would miss them.
# An expectation that holds passes as soon as it does; only a failing one waits longer.
expect.set_options(timeout=30_000)


class Stack:
    def __init__(self, api: ManagedProcess, worker: ManagedProcess) -> None:
        self.api, self.worker = api, worker
        self.url = f"http://127.0.0.1:{api.port}"


@pytest.fixture(scope="session")
def stack(redis_server, s3_server, tmp_path_factory) -> Iterator[Stack]:
    """One API and worker for every page test file (in each pytest-xdist process): the page
    tests find their own jobs by id or as the newest, so they share it. Redis database 3 is
    no other test's, so this worker, idle until the session ends, takes no one else's tasks."""
    if not (STATIC_DIR / "index.html").is_file():
        pytest.fail(f"the page is not built in {STATIC_DIR}: run scripts/setup (needs node and npm)")
    tmp = tmp_path_factory.mktemp("web-stack")
    # A lost task is found by the watchdog after job_stall_timeout_s (120 s by default, as long
    # as a page test waits for a job): here within ~25 s, so a task lost under CI's load costs a
    # page test a delay, not a failure (the recovery itself is tested in tests/service).
    env = service_env(redis_server.port, s3_server.port, db=3, bucket="web-e2e",
                      JOB_STALL_TIMEOUT_S="20", WATCHDOG_INTERVAL_S="5")
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=1)
    yield Stack(api, worker)
    worker.stop()
    api.stop()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[pytest.TestReport]:
    """A failed page test's report carries the ends of the API's and the worker's logs: a job
    that stays queued under CI's load is then explained by what the stack did meanwhile."""
    report: pytest.TestReport = yield
    stack = getattr(item, "funcargs", {}).get("stack")
    if report.failed and call.when == "call" and isinstance(stack, Stack):
        # where a task that never ended stands (prism_worker.app); the end kept long enough to show
        # the tasks before the dump too (a dump alone is ~6,000 characters)
        stack.worker.dump_stacks()
        for name, process in (("worker", stack.worker), ("API", stack.api)):
            report.sections.append((f"the {name}'s log, its end", process.log[-30000:]))
    return report


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    if not CHROMIUM.exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup as root, or apt-get install chromium")
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield browser
        browser.close()


@pytest.fixture
def page(browser, stack) -> Iterator[Page]:
    """A fresh tab on the page; fails the test on any script error or refused resource (CSP)."""
    context = browser.new_context(viewport=VIEWPORT, base_url=stack.url)
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda exc: problems.append(f"uncaught: {exc}"))
    # HTTP error answers are logged as "Failed to load resource": those are the tests' own doing.
    page.on("console", lambda m: problems.append(m.text) if m.type == "error"
            and not m.text.startswith("Failed to load resource") else None)
    page.goto("/")
    yield page
    context.close()
    _cancel_left_jobs(stack)
    assert not problems, problems


def _cancel_left_jobs(stack: Stack) -> None:
    """Cancel every job a test left queued or running: the stack's one worker (concurrency 1) is
    shared by the page tests, and a job left behind (a station folder's batch, a job the test did
    not wait for) made the next test's job wait "Queued" behind its items until that test's 120 s
    ran out (CI; the worker's stack dump showed it busy finishing other jobs' items)."""
    with httpx.Client(base_url=stack.url, timeout=30) as http:
        for key in API_KEYS.values():
            headers = {"X-API-Key": key}
            for state in ("queued", "running"):
                listed = http.get("/v1/jobs", params={"state": state, "items": "false", "limit": 200},
                                  headers=headers)
                listed.raise_for_status()
                for job in listed.json()["jobs"]:
                    done = http.post(f"/v1/jobs/{job['id']}/cancel", headers=headers)
                    assert done.status_code in (200, 409), done.text  # 409: it ended meanwhile

"""A page test that fails on a job that never ends prints where the worker stands: SIGUSR2 to the
worker's group makes every pool child print its threads' stacks into the worker's log
(prism_worker.app), and the worker lives on."""

from __future__ import annotations

import re
import time


def _wait_for(condition, timeout_s: float = 60) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.2)
    return True


def test_sigusr2_prints_each_pool_childs_stacks_into_the_log(stack):
    # A child registers its handler when it starts: wait until the pool is up.
    assert _wait_for(lambda: "ready." in stack.worker.log), stack.worker.log[-2000:]
    before = len(stack.worker.log)
    stack.worker.dump_stacks(settle_s=0.5)
    assert _wait_for(lambda: "most recent call first" in stack.worker.log[before:]), stack.worker.log[before:]
    dumped = stack.worker.log[before:]
    # faulthandler's own format: each thread's header, then its frames, innermost first. The main
    # process and its pool child write at once into the one log, so their lines may interleave:
    # counted, not matched as a block. One dump per process at least (concurrency 1,
    # tests/web/conftest.py): a header each, and the child's task loop among the frames.
    assert _wait_for(lambda: stack.worker.log[before:].count("(most recent call first):") >= 2, 10), dumped
    dumped = stack.worker.log[before:]
    assert dumped.count('  File "') >= 2 and re.search(r"0x[0-9a-f]{8,}", dumped), dumped
    assert stack.worker.proc.poll() is None  # the signal did not end it
    assert "SoftTimeLimitExceeded" not in dumped  # nor interrupt a task (USR1 would)

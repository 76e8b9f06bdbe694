"""The reason a task gave up, as a client can read it: which backend, not its internal address.

Exception messages are not quoted: they may name internal hosts, buckets or keys.
"""

from __future__ import annotations

import redis
from billiard.exceptions import SoftTimeLimitExceeded, TimeLimitExceeded
from botocore.exceptions import ClientError, ConnectionError, HTTPClientError

__all__ = ["failure_reason"]


def failure_reason(exc: BaseException, retries: int, time_limit_s: float | None = None) -> str:
    """One line: what failed, and how many retries were spent on it. `time_limit_s`: the
    task's soft time limit, named when that is what stopped it."""
    if isinstance(exc, SoftTimeLimitExceeded | TimeLimitExceeded):
        of = f" of {time_limit_s:g} s" if time_limit_s else ""
        return (f"took longer than the worker's time limit{of}: the input may be too large for "
                "one task (fewer frames, a smaller photo), or the operator can raise "
                "PRISM_TASK_TIME_LIMIT_S")
    if isinstance(exc, ConnectionError | HTTPClientError):  # refused, timed out, reset
        what = "the object store was unreachable"
    elif isinstance(exc, ClientError):
        code = exc.response.get("Error", {}).get("Code", "?")
        what = f"the object store refused a request ({code})"
    elif isinstance(exc, redis.ConnectionError | redis.TimeoutError):
        what = "the job store (Redis) was unreachable"
    else:
        what = f"internal error: {type(exc).__name__}"
    return what + (f" (gave up after {retries} retries)" if retries else "")

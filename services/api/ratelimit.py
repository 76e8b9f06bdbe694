"""Rate limits shared by every API process: the generic cell rate algorithm in Redis.

Used per tenant (every call) and per client address (refused keys). Each subject has one Redis
key holding its "theoretical arrival time" (TAT): the time by which its calls so far would have
been spent at the allowed rate. A call is let through while the TAT is less than one burst ahead
of now, and moves it on by one interval. One Lua script reads and moves it atomically, on
Redis's own clock, so API processes on several hosts (with clocks of their own) share one
budget. The key is named after a hash of the subject (never an API key).
"""

from __future__ import annotations

import hashlib
import math

import redis

__all__ = ["RateLimiter"]

# KEYS[1] the subject's TAT (microseconds); ARGV[1] interval (us), ARGV[2] burst (us), ARGV[3]
# 1 to count the call, 0 to only look. Returns 0 when the call may go ahead (counting it if
# asked), else the microseconds to wait before it would (counting nothing): the look and the
# count are one step, so callers racing each other cannot all slip through on the last token.
_GCRA = """
local t = redis.call('TIME')
local now = tonumber(t[1]) * 1000000 + tonumber(t[2])
local interval, burst = tonumber(ARGV[1]), tonumber(ARGV[2])
local tat = tonumber(redis.call('GET', KEYS[1]) or '0')
if tat < now then tat = now end
local wait = tat + interval - burst - now
if wait > 0 then return wait end
if ARGV[3] == '0' then return 0 end
redis.call('SET', KEYS[1], tostring(tat + interval), 'PX', math.ceil((tat + interval - now) / 1000) + 1)
return 0
"""


class RateLimiter:
    """`per_minute` calls a minute per subject, in bursts of up to `per_minute`.

    `scope` names the budget ("rate" per tenant, "authfail" per address): each its own keys.
    """

    def __init__(self, client: redis.Redis, per_minute: int, scope: str = "rate") -> None:
        self._script = client.register_script(_GCRA)
        self.per_minute = per_minute
        self._scope = scope
        self._interval_us = 60_000_000 // max(per_minute, 1)

    def wait_s(self, subject: str, *, count: bool = True) -> float:
        """0.0 if the subject's call may go ahead now (counted unless `count` is False), else
        the seconds to wait before it would (and nothing is counted)."""
        if self.per_minute <= 0:
            return 0.0
        key = f"prism:{self._scope}:" + hashlib.sha256(subject.encode()).hexdigest()[:32]
        wait_us = int(self._script(keys=[key], args=[self._interval_us,
                                                     self._interval_us * self.per_minute,
                                                     1 if count else 0]))
        return wait_us / 1e6

    @staticmethod
    def retry_after(wait_s: float) -> str:
        """The Retry-After header value: whole seconds, rounded up, at least 1."""
        return str(max(1, math.ceil(wait_s)))

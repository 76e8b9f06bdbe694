"""kombu's Redis transports (plain and Sentinel) with one fix: a worker survives its Redis
going away while it holds unacknowledged messages.

The failure (kombu 5.7.0, the newest release; kombu issues #970, #582): when the broker
connection breaks, Celery's consumer calls ``Connection.collect()`` and then ``close()``.
``collect`` closes the transport's channels one by one, and a channel whose close fails on
the dead socket (its pending BRPOP, or restoring its unacked messages with Redis down) stops
the loop, leaving the channels after it open; ``collect`` then detaches the transport from
the connection (``transport.client = None``). The later ``close()`` closes the channel that
was left open: restoring its unacked messages builds a new connection pool from
``transport.client``, and ``None.hostname`` raises AttributeError, which is not a connection
error, so the worker's main process exits ("Unrecoverable error"). A task that finishes after
the reconnect and acknowledges on that old channel fails the same way.

The channels here remember the connection they were opened on and build their pools from it
when the transport has been detached: the restore then reaches Redis if it is back (or fails
with a connection error, which Celery handles, and the messages come back after the
visibility timeout), and a late acknowledgement is delivered.
tests/service/test_redis_restart.py reproduces both with kombu alone and with a real worker.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from kombu.transport import redis as kombu_redis

__all__ = ["SentinelTransport", "Transport", "transport_for"]


class _RemembersConnection:
    """Mixin for kombu's Redis channels: pools are built from the channel's own connection."""

    connection: Any  # the transport

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._conninfo = self.connection.client  # the kombu Connection (URL, options)

    @contextmanager
    def _attached(self) -> Iterator[None]:
        transport = self.connection
        if transport.client is not None:
            yield
            return
        # Detached by Connection.collect(): lend the transport the connection it had, for
        # the time it takes to read the parameters (the worker's loop is single-threaded).
        transport.client = self._conninfo
        try:
            yield
        finally:
            transport.client = None

    def _get_pool(self, asynchronous: bool = False) -> Any:
        with self._attached():
            return super()._get_pool(asynchronous)  # type: ignore[misc]


class Channel(_RemembersConnection, kombu_redis.Channel):
    pass


class SentinelChannel(_RemembersConnection, kombu_redis.SentinelChannel):
    pass


class Transport(kombu_redis.Transport):
    Channel = Channel


class SentinelTransport(kombu_redis.SentinelTransport):
    Channel = SentinelChannel


def transport_for(url: str) -> str:
    """Celery's ``broker_transport`` for a ``redis://``, ``rediss://`` or ``sentinel://`` URL."""
    name = "SentinelTransport" if url.startswith("sentinel://") else "Transport"
    return f"{__name__}:{name}"

"""The client's errors, apart from the client (httpx, the API's models) so that `prism`'s error
policy (`main.main`) can catch them without importing it for every command."""

from __future__ import annotations

from typing import Any

__all__ = ["ApiError", "WaitTimeoutError"]


class ApiError(Exception):
    """The API refused a request (4xx/5xx) or could not be reached; the message says why.

    status : the HTTP status, None when the API could not be reached
    problem : the RFC 9457 problem document the API answered with (empty if none)
    """

    def __init__(self, message: str, *, status: int | None = None,
                 problem: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.problem = problem or {}

    @property
    def unavailable(self) -> bool:
        """The service, not the request, is at fault: unreachable, a 5xx, or a 429 that outlasted
        the retries. The same request may succeed later."""
        return self.status is None or self.status >= 500 or self.status == 429


class WaitTimeoutError(ApiError):
    """`ApiClient.wait` gave up: the job was not final after the time allowed (it may still be)."""

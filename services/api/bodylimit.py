"""A cap on request bodies, enforced while they arrive.

FastAPI reads a JSON body whole before any dependency runs, the API key check included, so
without a cap anyone could make an API process buffer as much as they care to send. Uploads
have their own, larger limit (routes/uploads.py) and are checked after the key, so they pass.
So does a station (POST /v1/stations: the photos to calibrate it from, a dozen or more full-size
photos, or its station.json with the plate), read by its route after the key check: it has a cap
of its own, `Settings.station_max_bytes` (PRISM_STATION_MAX_BYTES), counted as it arrives.
A declared Content-Length over the cap is refused unread; a chunked body is counted as it comes
and refused as soon as it passes the cap.
"""

from __future__ import annotations

import re

from fastapi import HTTPException, status
from prism_common.settings import get_settings
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .problems import instance_of, problem_response

__all__ = ["BodyLimit"]

_EXEMPT = ("/v1/uploads",)  # streamed to storage under PRISM_UPLOAD_MAX_BYTES
_STATIONS = "/v1/stations"  # under PRISM_STATION_MAX_BYTES
# and a station's verification photos (a reference part in 5 or more placements)
_VERIFICATIONS = re.compile(r"/v1/stations/[^/]+/verifications")


def _too_large(limit: int, setting: str = "PRISM_REQUEST_MAX_BYTES") -> str:
    return f"the request body is larger than {limit} bytes ({setting})"


def _multipart(scope: Scope) -> bool:
    sent: bytes = dict(scope["headers"]).get(b"content-type", b"")
    return sent.split(b";", 1)[0].strip().lower() == b"multipart/form-data"


class BodyLimit:
    """ASGI middleware: 413 for bodies over `Settings.request_max_bytes`, outside uploads;
    a station's calibration photos (multipart) over `Settings.station_max_bytes`."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        # The route's own path: under uvicorn --root-path the scope's path carries the prefix.
        path, root = scope.get("path", ""), scope.get("root_path", "")
        if root and path.startswith(root):
            path = path[len(root):]
        if scope["type"] != "http" or path.rstrip("/") in _EXEMPT:
            await self.app(scope, receive, send)
            return
        # The settings the routes see, overrides included (as in main.lifespan).
        settings = scope["app"].dependency_overrides.get(get_settings, get_settings)()
        limit, setting = settings.request_max_bytes, "PRISM_REQUEST_MAX_BYTES"
        route = path.rstrip("/")
        photos = route == _STATIONS or _VERIFICATIONS.fullmatch(route) is not None
        if photos and scope.get("method") == "POST" and _multipart(scope):
            # Photos to calibrate a station from; a station.json (one plate) stays under the
            # request's cap: the JSON body is held whole and parsed.
            limit, setting = settings.station_max_bytes, "PRISM_STATION_MAX_BYTES"
        length = dict(scope["headers"]).get(b"content-length", b"")
        if length.isdigit() and int(length) > limit:
            response = problem_response(status.HTTP_413_CONTENT_TOO_LARGE, _too_large(limit, setting),
                                        instance=instance_of(scope), headers={"Connection": "close"})
            await response(scope, receive, send)
            return
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, _too_large(limit, setting),
                                        headers={"Connection": "close"})
            return message

        await self.app(scope, counted, send)

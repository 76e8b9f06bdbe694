"""The FastAPI application: wiring only (routers, error shapes, startup)."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import redis
from boto3.exceptions import S3UploadFailedError
from botocore.exceptions import BotoCoreError
from fastapi import APIRouter, FastAPI, Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from prism_common.settings import get_settings

from .bodylimit import BodyLimit
from .deps import get_objects
from .routes import health, jobs, previews, upload_video, uploads
from .webapp import mount_web

__all__ = ["app", "create_app"]

log = logging.getLogger(__name__)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    # The settings the routes will see, overrides included, so tests start on their own bucket.
    settings = app.dependency_overrides.get(get_settings, get_settings)()
    await anyio.to_thread.run_sync(get_objects(settings).ensure_bucket)
    yield


async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
    # Location, message and type only: FastAPI's default also echoes the input, which can hold
    # NaN (not JSON, so a 500) or a whole uploaded spec back at the client.
    detail = [{"loc": list(e.get("loc", ())), "msg": str(e.get("msg", "invalid")),
               "type": str(e.get("type", "value_error"))} for e in exc.errors()]
    return JSONResponse({"detail": detail}, status_code=status.HTTP_422_UNPROCESSABLE_CONTENT)


async def _backend_down(request: Request, exc: Exception) -> JSONResponse:
    log.error("backend unavailable on %s %s: %r", request.method, request.url.path, exc)
    return JSONResponse({"detail": "a storage backend is unavailable; try again shortly"},
                        status_code=status.HTTP_503_SERVICE_UNAVAILABLE)


_RETRY_AFTER = {"Retry-After": {"description": "Seconds to wait before trying again.",
                                "schema": {"type": "integer"}}}
_V1_RESPONSES: dict[int | str, dict] = {
    400: {"description": "A body that cannot be parsed at all (not JSON, cut multipart)"},
    401: {"description": "Missing or invalid X-API-Key"},
    429: {"description": "Rate limit of this key, or of refused keys from this address, exceeded",
          "headers": _RETRY_AFTER},
    503: {"description": "At capacity (Retry-After) or a backend is unavailable"},
}


def create_app() -> FastAPI:
    app = FastAPI(title="PrismCloud", version="1", lifespan=lifespan,
                  description="Measured 3D point clouds of box-shaped parts from photos.")
    v1 = APIRouter(prefix="/v1", responses=_V1_RESPONSES)
    v1.include_router(uploads.router)
    v1.include_router(upload_video.router)
    v1.include_router(jobs.router)
    v1.include_router(previews.router)
    app.include_router(v1)
    app.include_router(health.router)
    mount_web(app)
    app.add_middleware(BodyLimit)
    app.add_exception_handler(RequestValidationError, _invalid)
    for error in (redis.ConnectionError, redis.TimeoutError, BotoCoreError, S3UploadFailedError):
        app.add_exception_handler(error, _backend_down)
    return app


app = create_app()

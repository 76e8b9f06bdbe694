"""The FastAPI application: wiring only (routers, error shapes, startup)."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import redis
from boto3.exceptions import S3UploadFailedError
from botocore.exceptions import BotoCoreError
from fastapi import APIRouter, FastAPI
from fastapi.routing import APIRoute
from prism_common.settings import get_settings

from .bodylimit import BodyLimit
from .deps import get_objects
from .problems import declare_problems, install_handlers
from .routes import (
    health,
    jobs,
    previews,
    results,
    station_verifications,
    stations,
    upload_points,
    upload_video,
    uploads,
)
from .webapp import mount_docs, mount_guide, mount_web

__all__ = ["app", "create_app"]

log = logging.getLogger(__name__)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    # The settings the routes will see, overrides included, so tests start on their own bucket.
    settings = app.dependency_overrides.get(get_settings, get_settings)()
    await anyio.to_thread.run_sync(get_objects(settings).ensure_bucket)
    yield


_RETRY_AFTER = {"Retry-After": {"description": "Seconds to wait before trying again.",
                                "schema": {"type": "integer"}}}
_V1_RESPONSES: dict[int | str, dict] = {
    400: {"description": "A body that cannot be parsed at all (not JSON, cut multipart)"},
    401: {"description": "Missing or invalid X-API-Key. Refused from the headers: a request "
                          "carrying a body gets `Connection: close` and its body is not read"},
    429: {"description": "Rate limit of this key, or of refused keys from this address, exceeded",
          "headers": _RETRY_AFTER},
    413: {"description": "Body over PRISM_REQUEST_MAX_BYTES (uploads: PRISM_UPLOAD_MAX_BYTES; "
                          "POST /v1/stations: PRISM_STATION_MAX_BYTES)"},
    503: {"description": "At capacity or a backend is unavailable", "headers": _RETRY_AFTER},
}


def operation_id(route: APIRoute) -> str:
    """An operation's id is its handler's name (create_job, get_job): a generated client names
    its modules and functions after the ids, and FastAPI's default (create_job_v1_jobs_post)
    spells the path and method again. Handler names are unique across the routers."""
    return route.name


def create_app() -> FastAPI:
    # FastAPI's own /docs and /redoc load their scripts from a CDN: ours are served from the package.
    app = FastAPI(title="PrismCloud", version="1", lifespan=lifespan, docs_url=None, redoc_url=None,
                  description="Measured 3D point clouds of box-shaped parts from photos.",
                  generate_unique_id_function=operation_id)
    v1 = APIRouter(prefix="/v1", responses=_V1_RESPONSES)
    v1.include_router(uploads.router)
    v1.include_router(upload_video.router)
    v1.include_router(upload_points.router)
    v1.include_router(jobs.router)
    v1.include_router(previews.router)
    v1.include_router(results.router)
    v1.include_router(stations.router)
    v1.include_router(station_verifications.router)
    app.include_router(v1)
    app.include_router(health.router)
    mount_web(app)
    mount_docs(app)
    mount_guide(app)
    app.add_middleware(BodyLimit)
    install_handlers(app, (redis.ConnectionError, redis.TimeoutError, BotoCoreError, S3UploadFailedError))

    def openapi() -> dict[str, Any]:
        # Built once, as FastAPI does, then every error answer declared as a problem document.
        if app.openapi_schema is None:
            app.openapi_schema = stations.document_station(declare_problems(FastAPI.openapi(app)))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


app = create_app()

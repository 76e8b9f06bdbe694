"""Probes and metrics, for the orchestrator and Prometheus (no API key: they carry no job data)."""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable

import anyio
import httpx
import redis.asyncio as aioredis
from botocore.exceptions import BotoCoreError
from fastapi import APIRouter, Request, Response, status
from fastapi.responses import JSONResponse
from prism_common.redis_client import async_redis_client
from prism_common.settings import Settings
from prometheus_client import CONTENT_TYPE_LATEST

from ..collector import render_metrics
from ..deps import ObjectsDep, RedisDep, SettingsDep, StoreDep
from ..problems import problem_response

router = APIRouter(tags=["health"])
log = logging.getLogger(__name__)

PROBE_TIMEOUT_S = 2.0  # a probe answers within about this, whatever state the backends are in


@router.get("/healthz")
def healthz() -> dict[str, str]:
    """The process is alive (touches nothing else)."""
    return {"status": "ok"}


async def _redis_ok(settings: Settings) -> bool:
    # A client of its own with short timeouts: the shared one waits longer, for real work.
    client = async_redis_client(settings, socket_timeout=PROBE_TIMEOUT_S,
                                socket_connect_timeout=PROBE_TIMEOUT_S)
    try:
        return bool(await client.ping())
    except (aioredis.RedisError, OSError) as exc:
        log.warning("readyz: redis: %s", exc)
        return False
    finally:
        await client.aclose()


async def _object_store_ok(objects: ObjectsDep) -> bool:
    # boto3 retries for minutes; a presigned HEAD of the bucket (signed locally, no network)
    # checks endpoint, credentials and bucket in one request with our own timeout.
    try:
        url = objects.client.generate_presigned_url(
            "head_bucket", Params={"Bucket": objects.bucket}, ExpiresIn=60)
        async with httpx.AsyncClient(timeout=PROBE_TIMEOUT_S, trust_env=False) as client:
            answer = await client.head(url)
    except (httpx.HTTPError, BotoCoreError) as exc:  # BotoCoreError: no credentials found
        log.warning("readyz: object store: %s", exc)
        return False
    if answer.status_code != 200:
        log.warning("readyz: object store answered HTTP %s", answer.status_code)
    return answer.status_code == 200


@router.get("/readyz", responses={503: {"description": "A backend is down"}})
async def readyz(request: Request, settings: SettingsDep, objects: ObjectsDep) -> JSONResponse:
    """Redis and the object store answer: 200, or 503 naming which does not."""
    checks = {"redis": False, "object_store": False}

    async def run(name: str, probe: Callable[[], Awaitable[bool]]) -> None:
        with anyio.move_on_after(PROBE_TIMEOUT_S * 2):
            checks[name] = await probe()

    async with anyio.create_task_group() as group:
        group.start_soon(run, "redis", lambda: _redis_ok(settings))
        group.start_soon(run, "object_store", lambda: _object_store_ok(objects))
    body = {name: "ok" if ok else "down" for name, ok in checks.items()}
    if all(checks.values()):
        return JSONResponse(body, status_code=status.HTTP_200_OK)
    down = " and ".join(name.replace("_", " ") for name, ok in checks.items() if not ok)
    return problem_response(status.HTTP_503_SERVICE_UNAVAILABLE, f"{down} not answering",
                            instance=request.url.path, kind="backend-unavailable", checks=body)


@router.get("/metrics", response_class=Response,
            responses={200: {"content": {CONTENT_TYPE_LATEST: {}}}})
def metrics(store: StoreDep, client: RedisDep) -> Response:
    """Prometheus text: jobs by state, queue depth, task duration histograms."""
    return Response(render_metrics(store, client), media_type=CONTENT_TYPE_LATEST)


# Monitors probe with HEAD: the same answers without a body (its own routes, left out of the
# OpenAPI document, where a second method on one route would repeat the operation's id).
router.add_api_route("/healthz", healthz, methods=["HEAD"], include_in_schema=False)
router.add_api_route("/readyz", readyz, methods=["HEAD"], include_in_schema=False)

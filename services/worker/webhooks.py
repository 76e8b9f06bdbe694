"""Tell the client's system that a job ended: a signed POST of the job resource.

The body is the job as ``GET /v1/jobs/{id}`` shows it (download links included), signed with
HMAC-SHA256 over the exact bytes sent, so the receiver can check it came from us unaltered.
"""

from __future__ import annotations

import hashlib
import hmac

import httpx
from prism_common.public import JobPublic, to_public
from prism_common.records import JobRecord, State

from . import context
from .egress import check_target, send_pinned

__all__ = ["EVENT", "WebhookError", "deliver", "job_resource", "signature"]

EVENT = "job.finished"
TIMEOUT = httpx.Timeout(5.0)


class WebhookError(Exception):
    """The receiver did not take the delivery (no answer, or not 2xx); it is tried again."""


def job_resource(job: JobRecord) -> JobPublic:
    """The job as the API answers it, with presigned download links for finished items."""
    ttl, objects = context.settings().presign_ttl_s, context.link_objects()
    return to_public(job, lambda key, name: objects.presign_get(key, ttl, filename=name))


def signature(body: bytes) -> str:
    secret = context.settings().webhook_secret.get_secret_value().encode()
    return "sha256=" + hmac.new(secret, body, hashlib.sha256).hexdigest()


def deliver(job_id: str) -> None:
    """POST the ended job to its webhook_url.

    Raises
    ------
    ReferenceError
        The URL is not one the service may call (not retried: it will not change).
    WebhookError, httpx.HTTPError
        Not delivered this time.
    """
    job = context.store().get(job_id)
    if job is None or not job.webhook_url or job.state not in (State.succeeded, State.failed):
        return
    settings = context.settings()
    target = check_target(job.webhook_url, schemes={"http", "https"},
                          allowed_hosts=settings.webhook_allowed_hosts,
                          allow_private=settings.webhook_allow_private)
    body = job_resource(job).model_dump_json().encode()
    headers = {"Content-Type": "application/json", "X-Prism-Signature": signature(body),
               "X-Prism-Event": EVENT, "User-Agent": "PrismCloud-Webhook/1"}
    with httpx.Client(timeout=TIMEOUT, trust_env=False) as client, \
            send_pinned(client, "POST", target, content=body, headers=headers) as response:
        if not response.is_success:
            raise WebhookError(f"{job.webhook_url} answered HTTP {response.status_code}")

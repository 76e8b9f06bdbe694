"""Tell the client's system that a job ended: a POST of the job resource, signed by the
Standard Webhooks specification (https://www.standardwebhooks.com/) with the
`standardwebhooks` package, so a receiver can check it with any of the standard's libraries.

The body is the job as ``GET /v1/jobs/{id}`` shows it (download links included). Headers:

* ``webhook-id``: the same for every attempt at one job's event (a retry, a redelivery after a
  worker died), so a receiver that has seen it can drop the repeat;
* ``webhook-timestamp``: when this attempt was signed (Unix seconds): each retry is signed
  afresh, and receivers refuse a delivery more than 5 minutes off their clock (replays);
* ``webhook-signature``: ``v1,`` + base64 HMAC-SHA256 over ``{id}.{timestamp}.{body}`` with
  the key of ``PRISM_WEBHOOK_SECRET`` (`prism_common.webhook_secret`).

The target is checked by the webhook policy (`prism_common.outbound.check_webhook_url`, the
one the API applied at submit) before each attempt, and the request goes to the addresses
checked (`inputs.send_pinned`).
"""

from __future__ import annotations

from datetime import UTC, datetime

import httpx
from prism_common.outbound import check_webhook_url
from prism_common.public import JobPublic, to_public
from prism_common.records import ENDED_STATES, JobRecord
from prism_common.webhook_secret import signing_key
from standardwebhooks import Webhook

from .context import WorkerContext
from .inputs import pinned, send_pinned

__all__ = ["EVENT", "WebhookError", "deliver", "job_resource", "message_id", "signed_headers"]

EVENT = "job.finished"
TIMEOUT = httpx.Timeout(5.0)


class WebhookError(Exception):
    """The receiver did not take the delivery (no answer, or not 2xx); it is tried again."""


def job_resource(ctx: WorkerContext, job: JobRecord) -> JobPublic:
    """The job as the API answers it, with presigned download links for finished items."""
    ttl, objects = ctx.settings.presign_ttl_s, ctx.link_objects
    return to_public(job, lambda key, name: objects.presign_get(key, ttl, filename=name))


def message_id(job_id: str, event: str = EVENT) -> str:
    """The ``webhook-id`` of `event` for a job: one per job and event, whatever the attempt."""
    return f"{event}.{job_id}"


def signed_headers(msg_id: str, body: bytes, *, key: bytes, at: datetime) -> dict[str, str]:
    """The three Standard Webhooks headers for `body` signed with `key` at time `at` (UTC,
    counted in whole seconds as the header carries it)."""
    whole = datetime.fromtimestamp(int(at.timestamp()), tz=UTC)
    return {"webhook-id": msg_id, "webhook-timestamp": str(int(whole.timestamp())),
            "webhook-signature": Webhook(key).sign(msg_id, whole, body.decode())}


def deliver(ctx: WorkerContext, job_id: str) -> None:
    """POST the ended job to its webhook_url, signed now.

    Raises
    ------
    ReferenceError
        The URL is not one the service may call (not retried: it will not change).
    WebhookError, httpx.HTTPError
        Not delivered this time.
    """
    job = ctx.store.get(job_id)
    if job is None or not job.webhook_url or job.state not in ENDED_STATES:
        return
    settings = ctx.settings
    target = pinned(check_webhook_url(job.webhook_url, settings, resolve=True))
    body = job_resource(ctx, job).model_dump_json().encode()
    key = signing_key(settings.webhook_secret.get_secret_value())
    headers = {"Content-Type": "application/json", "User-Agent": "PrismCloud-Webhook/2",
               "X-Prism-Event": EVENT,
               **signed_headers(message_id(job.id), body, key=key, at=datetime.now(UTC))}
    with httpx.Client(timeout=TIMEOUT, trust_env=False) as client, \
            send_pinned(client, "POST", target, content=body, headers=headers) as response:
        if not response.is_success:
            raise WebhookError(f"{job.webhook_url} answered HTTP {response.status_code}")

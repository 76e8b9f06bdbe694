"""An item's input photos: read from where the reference points, copied into the job's prefix.

After the copy, every later task (tiles, finish, a re-run of the plan) reads the service's
own bucket only: the outside source is read once, and only here, where the rules are checked.
"""

from __future__ import annotations

from botocore.exceptions import ClientError
from prism_common.records import JobRecord
from prism_common.references import ReferenceError, check_reference, parse_reference
from prism_common.storage import is_missing

from . import context
from .fetch import fetch_url
from .keys import item_key

__all__ = ["copy_input"]

# Besides a missing object: a bucket that is not there or not ours to read is "no object" too.
_UNREADABLE = {"403", "AccessDenied", "NoSuchBucket"}


def _read_s3(bucket: str, key: str, text: str, limit: int) -> bytes:
    try:
        obj = context.objects().client.get_object(Bucket=bucket, Key=key)
    except ClientError as exc:
        if is_missing(exc) or exc.response.get("Error", {}).get("Code") in _UNREADABLE:
            raise ReferenceError(f"no object {text!r}") from None
        raise  # anything else is the store's trouble, retried by the task
    with obj["Body"] as body:
        if obj.get("ContentLength", 0) > limit:
            raise ReferenceError(f"{text!r} is {obj['ContentLength']} bytes, over the limit of {limit}")
        return body.read()


def _read(text: str, tenant: str) -> tuple[bytes, str]:
    """The bytes a reference names, and the name to quote in error messages."""
    ref = parse_reference(text)
    settings = context.settings()
    upload = context.store().get_upload(ref.upload_id) if ref.kind == "upload" else None
    # The API checked the reference when the job came in; the rules (or the upload) may have
    # changed since, so they are checked again where the bytes are read.
    check_reference(ref, settings, tenant=tenant, upload_owner=upload["tenant"] if upload else None)
    if ref.kind == "upload":
        assert upload is not None
        data = _read_s3(context.objects().bucket, upload["key"], text, settings.upload_max_bytes)
        return data, upload.get("name") or text
    if ref.kind == "s3":
        return _read_s3(ref.bucket, ref.key, text, settings.fetch_max_bytes), text
    return fetch_url(ref.url, settings), ref.url


def copy_input(job: JobRecord, item: int, which: str) -> tuple[str, str]:
    """Copy the item's `which` ("front" or "side") photo into the job's prefix, unless done.

    Returns the object key and the name to quote in error messages (the uploaded file's name,
    or the reference).

    Raises
    ------
    ReferenceError
        A reference the service will not read, or one that names nothing.
    FetchError
        An https input that could not be fetched.
    """
    spec = job.items[item].spec
    text = spec.image if which == "front" else spec.side_image
    assert text is not None
    key = item_key(job.id, item, which)
    objects = context.objects()
    if objects.exists(key):
        return key, _label(text)
    data, label = _read(text, job.tenant)
    objects.put_bytes(key, data)
    return key, label


def _label(text: str) -> str:
    ref = parse_reference(text)
    if ref.kind == "upload":
        upload = context.store().get_upload(ref.upload_id)
        return (upload or {}).get("name") or text
    return text

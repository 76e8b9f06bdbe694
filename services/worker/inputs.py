"""An item's inputs: read from where the reference points, with the rules checked again here.

A tiled item's photos are copied into the job's prefix, so its later tasks (tiles, finish, a
re-run of the plan) read the service's own bucket only. A batch item reads its photo directly
(`read_input`); a video is streamed to a local file (`save_input`) and split from there.
"""

from __future__ import annotations

import shutil
from typing import BinaryIO

from botocore.exceptions import ClientError
from prism_common.records import ItemView
from prism_common.references import ReferenceError, check_reference, parse_reference
from prism_common.storage import is_missing

from . import context
from .fetch import fetch_url
from .keys import item_key

__all__ = ["copy_input", "read_input", "save_input"]

# Besides a missing object: a bucket that is not there or not ours to read is "no object" too.
_UNREADABLE = {"403", "AccessDenied", "NoSuchBucket"}
_CHUNK = 1 << 20


def _read_s3(bucket: str, key: str, text: str, limit: int, dest: BinaryIO | None = None) -> bytes:
    """The object's bytes; or, given `dest`, the object streamed into it (and b"")."""
    try:
        obj = context.objects().client.get_object(Bucket=bucket, Key=key)
    except ClientError as exc:
        if is_missing(exc) or exc.response.get("Error", {}).get("Code") in _UNREADABLE:
            raise ReferenceError(f"no object {text!r}") from None
        raise  # anything else is the store's trouble, retried by the task
    with obj["Body"] as body:
        if obj.get("ContentLength", 0) > limit:
            raise ReferenceError(f"{text!r} is {obj['ContentLength']} bytes, over the limit of {limit}")
        if dest is None:
            return body.read()
        shutil.copyfileobj(body, dest, _CHUNK)
        return b""


def _read(text: str, tenant: str, dest: BinaryIO | None = None) -> tuple[bytes, str]:
    """The bytes a reference names (or, given `dest`, b"" and the bytes written into it), and the
    name to quote in error messages."""
    ref = parse_reference(text)
    settings = context.settings()
    upload = context.store().get_upload(ref.upload_id) if ref.kind == "upload" else None
    # The API checked the reference when the job came in; the rules (or the upload) may have
    # changed since, so they are checked again where the bytes are read.
    check_reference(ref, settings, tenant=tenant, upload_owner=upload["tenant"] if upload else None)
    if ref.kind == "upload":
        assert upload is not None
        data = _read_s3(context.objects().bucket, upload["key"], text, settings.upload_max_bytes, dest)
        return data, upload.get("name") or text
    if ref.kind == "s3":
        return _read_s3(ref.bucket, ref.key, text, settings.fetch_max_bytes, dest), text
    return fetch_url(ref.url, settings, dest), ref.url


def read_input(view: ItemView, which: str) -> tuple[bytes, str]:
    """The bytes of the item's `which` ("front" or "side") photo, read where its reference
    points (not copied), and the name to quote in error messages.

    Raises ReferenceError or FetchError, as `copy_input` does.
    """
    spec = view.item.spec
    text = spec.image if which == "front" else spec.side_image
    assert text is not None
    return _read(text, view.tenant)


def save_input(view: ItemView, which: str, dest: BinaryIO) -> str:
    """Stream the item's `which` input into `dest` (a video: never whole in memory); the name
    to quote in error messages. Raises ReferenceError or FetchError, as `copy_input` does."""
    text = view.item.spec.image if which == "front" else view.item.spec.side_image
    assert text is not None
    return _read(text, view.tenant, dest)[1]


def copy_input(view: ItemView, which: str) -> tuple[str, str]:
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
    spec = view.item.spec
    text = spec.image if which == "front" else spec.side_image
    assert text is not None
    key = item_key(view.job_id, view.item.index, which)
    objects = context.objects()
    if objects.exists(key):
        return key, _label(text)
    data, label = _read(text, view.tenant)
    objects.put_bytes(key, data)
    return key, label


def _label(text: str) -> str:
    ref = parse_reference(text)
    if ref.kind == "upload":
        upload = context.store().get_upload(ref.upload_id)
        return (upload or {}).get("name") or text
    return text

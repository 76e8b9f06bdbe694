"""POST /v1/uploads: a photo streamed into object storage, to be named by jobs as upload:ID."""

from __future__ import annotations

from typing import Any
from uuid import uuid4

import anyio
from fastapi import APIRouter, HTTPException, Request, status
from fastapi.concurrency import run_in_threadpool
from prism_common.upload_keys import upload_key

from ..deps import ObjectsDep, SettingsDep, StoreDep, TenantDep
from ..schemas import UploadPublic
from ..upload_stream import MULTIPART_OVERHEAD, MultipartFile

router = APIRouter(prefix="/uploads", tags=["uploads"])

# The body is read by hand (streamed, size-limited), so its shape is declared for the docs here.
_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {"multipart/form-data": {
    "schema": {"type": "object", "required": ["file"],
               "properties": {"file": {"type": "string", "format": "binary"}}}}}}}


@router.post("", status_code=status.HTTP_201_CREATED, response_model=UploadPublic,
             openapi_extra=_BODY, responses={413: {"description": "Larger than the upload limit"},
                                                422: {"description": "No non-empty multipart `file`"}})
async def create_upload(request: Request, tenant: TenantDep, settings: SettingsDep,
                        store: StoreDep, objects: ObjectsDep) -> UploadPublic:
    """Stream the multipart field `file` into object storage; refused (413) past the size limit."""
    limit = settings.upload_max_bytes
    length = request.headers.get("content-length", "")
    if length.isdigit() and int(length) > limit + MULTIPART_OVERHEAD:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE,  # refused unread
                            f"the upload is larger than {limit} bytes", headers={"Connection": "close"})
    upload = MultipartFile(request, "file", limit)
    upload_id = uuid4().hex
    key = upload_key(tenant, upload_id)
    try:
        await anyio.to_thread.run_sync(objects.put_stream, key, upload)
    except Exception:
        if upload.failure is not None:  # our own refusal, possibly wrapped by boto3
            raise upload.failure from None
        raise
    finally:
        await upload.aclose()
    await run_in_threadpool(store.put_upload, upload_id, tenant=tenant, key=key, size=upload.size,
                            name=upload.name)
    return UploadPublic(id=upload_id, reference=f"upload:{upload_id}", size=upload.size,
                        name=upload.name)

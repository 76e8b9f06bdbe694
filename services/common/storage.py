"""Object storage through boto3, against any S3-compatible endpoint (AWS S3, MinIO, SeaweedFS).

Keys are built from checked segments only (`object_key`), so no input can name an object
outside the prefix it belongs in.
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any, BinaryIO

import boto3
from boto3.s3.transfer import TransferConfig
from botocore.client import Config
from botocore.exceptions import ClientError
from botocore.response import StreamingBody

from .settings import Settings

if TYPE_CHECKING:  # boto3-stubs[s3] (test extra): the client's types, not needed at run time
    from mypy_boto3_s3 import S3Client
    from mypy_boto3_s3.type_defs import ObjectIdentifierTypeDef

__all__ = ["ObjectStore", "is_missing", "object_key"]

SINGLE_PUT_BYTES = 64 * 2**20
_AS_BYTES = 8 * 2**20  # a seekable stream up to this size is read and sent whole
# A stream of unknown size (an upload read off its request) goes up in parts of 8 MiB; s3transfer
# holds up to 10 of them in memory by default (80 MiB an upload). Two let one part go up while the
# next is read from a client, which is slower than the store; with the API's cap on uploads at
# once (PRISM_UPLOADS_AT_ONCE) this bounds what uploads hold.
_STREAM = TransferConfig()
_STREAM.max_in_memory_upload_chunks = 2  # s3transfer's own setting, which boto3's __init__ omits
_SEGMENT = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")


def object_key(*segments: str | int) -> str:
    """Join checked segments with '/': each one a plain name, never '..', '/' or empty."""
    parts = [str(s) for s in segments]
    for part in parts:
        if not _SEGMENT.match(part) or ".." in part:
            raise ValueError(f"unsafe object key segment {part!r}")
    return "/".join(parts)


def is_missing(exc: ClientError) -> bool:
    """Does the S3 error say the object is not there?"""
    return exc.response.get("Error", {}).get("Code") in ("404", "NoSuchKey", "NotFound")


class ObjectStore:
    """The service's bucket (and read access to configured input buckets)."""

    def __init__(self, client: S3Client, bucket: str) -> None:
        self.client = client
        self.bucket = bucket

    @classmethod
    def from_settings(cls, settings: Settings, *, for_links: bool = False) -> ObjectStore:
        """The service's bucket; `for_links`: at the public endpoint, to presign downloads."""
        endpoint = settings.s3_endpoint_url
        if for_links and settings.s3_public_endpoint_url:
            endpoint = settings.s3_public_endpoint_url
        secret = settings.s3_secret_access_key
        key_id = settings.s3_access_key_id
        # No SHA-256 of every body for the signature (payload_signing_enabled False): over
        # https botocore leaves it out of uploads that carry a checksum anyway, but over plain
        # http (SeaweedFS or MinIO inside a cluster) it hashed every byte, half of an upload's
        # CPU (benchmarks/worker_cost.py). Uploads keep botocore's CRC32 checksum, pinned on
        # ("when_supported") so that AWS_REQUEST_CHECKSUM_CALCULATION=when_required, often set
        # for older S3-compatible servers, cannot leave an upload with no integrity check at all.
        client = boto3.client(
            "s3",
            endpoint_url=endpoint,
            region_name=settings.s3_region,
            aws_access_key_id=key_id.get_secret_value() if key_id else None,
            aws_secret_access_key=secret.get_secret_value() if secret else None,
            config=Config(signature_version="s3v4",
                          s3={"addressing_style": "path", "payload_signing_enabled": False},
                          request_checksum_calculation="when_supported",
                          retries={"max_attempts": 5, "mode": "standard"},
                          connect_timeout=5, read_timeout=60),
        )
        return cls(client, settings.s3_bucket)

    def ensure_bucket(self) -> None:
        try:
            self.client.head_bucket(Bucket=self.bucket)
        except ClientError:
            self.client.create_bucket(Bucket=self.bucket)

    def put_bytes(self, key: str, data: bytes, content_type: str = "application/octet-stream") -> None:
        self.client.put_object(Bucket=self.bucket, Key=key, Body=data, ContentType=content_type)

    def put_stream(self, key: str, stream: BinaryIO,
                   content_type: str = "application/octet-stream") -> None:
        """Stream a file object up without holding it in memory.

        A seekable stream under SINGLE_PUT_BYTES goes up in one PUT (multipart's part
        requests and thread pool cost more than they save there); larger or unseekable ones
        go up as multipart uploads.
        """
        if getattr(stream, "seekable", lambda: False)():  # a request-body reader is not
            start = stream.tell()
            size = stream.seek(0, 2) - start
            stream.seek(start)
            if size <= _AS_BYTES:
                # as bytes: http.client sends a file object 8 KiB at a time, a read and a send
                # for each (a 1 MB cloud: 128 of them, besides the checksum's and signature's
                # passes over the file)
                self.put_bytes(key, stream.read(size), content_type)
                return
            if size <= SINGLE_PUT_BYTES:
                self.client.put_object(Bucket=self.bucket, Key=key, Body=stream,
                                       ContentLength=size, ContentType=content_type)
                return
        self.client.upload_fileobj(stream, self.bucket, key, ExtraArgs={"ContentType": content_type},
                                   Config=_STREAM)

    def put_json(self, key: str, value: object) -> None:
        self.put_bytes(key, (json.dumps(value, indent=2) + "\n").encode(), "application/json")

    def get_json(self, key: str) -> Any:
        """The JSON document at `key`, or None when there is no such object."""
        try:
            return json.loads(self.get_bytes(key))
        except ClientError as exc:
            if is_missing(exc):
                return None
            raise

    def get_bytes(self, key: str, *, bucket: str | None = None) -> bytes:
        return self.client.get_object(Bucket=bucket or self.bucket, Key=key)["Body"].read()

    def get_head(self, key: str, size: int) -> bytes:
        """The object's first `size` bytes (all of it when shorter)."""
        return self.client.get_object(Bucket=self.bucket, Key=key, Range=f"bytes=0-{size - 1}")["Body"].read()

    def open(self, key: str) -> tuple[StreamingBody, int]:
        """The object's body, to be read in chunks and closed by the caller, and its size."""
        got = self.client.get_object(Bucket=self.bucket, Key=key)
        return got["Body"], int(got["ContentLength"])

    def exists(self, key: str) -> bool:
        try:
            self.client.head_object(Bucket=self.bucket, Key=key)
        except ClientError as exc:
            if is_missing(exc):
                return False
            raise
        return True

    def list_keys(self, prefix: str) -> list[str]:
        paginator = self.client.get_paginator("list_objects_v2")
        return [obj["Key"] for page in paginator.paginate(Bucket=self.bucket, Prefix=prefix)
                for obj in page.get("Contents", [])]

    def delete_keys(self, keys: list[str]) -> None:
        """Delete these objects (missing ones are no error), in batches of 1000."""
        for start in range(0, len(keys), 1000):
            batch: list[ObjectIdentifierTypeDef] = [{"Key": k} for k in keys[start:start + 1000]]
            answer = self.client.delete_objects(Bucket=self.bucket,
                                                Delete={"Objects": batch, "Quiet": True})
            # Failures come back in the body of an HTTP 200: raise, so nothing is forgotten.
            if errors := answer.get("Errors"):
                first = errors[0]
                raise OSError(f"could not delete {len(errors)} objects, e.g. {first.get('Key')!r}: "
                              f"{first.get('Code')} {first.get('Message')}")

    def presign_get(self, key: str, ttl_s: int, filename: str | None = None) -> str:
        params = {"Bucket": self.bucket, "Key": key}
        if filename:
            params["ResponseContentDisposition"] = f'attachment; filename="{filename}"'
        return self.client.generate_presigned_url("get_object", Params=params, ExpiresIn=ttl_s)

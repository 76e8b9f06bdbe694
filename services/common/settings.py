"""The service's configuration: one pydantic-settings class, read from PRISM_* variables."""

from __future__ import annotations

from functools import lru_cache
from typing import Annotated

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from prismcore.spec import OutputFormat

from .webhook_secret import signing_key

__all__ = ["Settings", "get_settings"]

# Typed, so that mypy checks these against OutputFormat's names. The text cloud and PLY, as the
# design promises (1.9 MB stored per 1280x1024 photo at the default 1 mm spacing, about 25 MB at
# one point per pixel); PRISM_DEFAULT_FORMATS='["laz","glb"]' (1.4 MB at 1 mm, 3.5 MB per pixel)
# for the compact ones, which go to items with a scale only (they are in mm: an item without one
# gets csv and ply, prism_api.routes.jobs._formats).
_DEFAULT_FORMATS: tuple[OutputFormat, ...] = ("csv", "ply")


class Settings(BaseSettings):
    """Every setting, with its environment variable PRISM_<NAME>.

    Secrets (`api_keys`, `webhook_secret`) have no default: the service refuses to start
    without them.
    """

    # Errors never echo the input: it holds the secrets (a malformed whsec_ webhook secret, say).
    model_config = SettingsConfigDict(env_prefix="PRISM_", extra="ignore", hide_input_in_errors=True)

    # Who may call: {"tenant name": "api key"}, e.g. PRISM_API_KEYS='{"acme": "k-..."}'.
    api_keys: dict[str, SecretStr]
    # Standard Webhooks signing key: "whsec_" + base64 (the standard's form), or any other
    # string, whose UTF-8 bytes are the key (prism_common.webhook_secret).
    webhook_secret: SecretStr = Field(description="Key for webhook signatures (Standard Webhooks).")

    redis_url: str = "redis://127.0.0.1:6379/0"
    # Redis behind Sentinel (prism_common.redis_client): PRISM_REDIS_SENTINELS=host:port,host:port
    # names the sentinels, which say where the primary named PRISM_REDIS_SENTINEL_MASTER is;
    # redis_url then gives only the primary's password and database number.
    redis_sentinels: Annotated[list[str], NoDecode] = Field(default_factory=list)
    redis_sentinel_master: str = "prism"
    redis_sentinel_password: SecretStr | None = None  # the sentinels' own (requirepass)
    s3_endpoint_url: str | None = None  # None: AWS S3
    # The store as clients reach it, for the presigned download links (the signature covers the
    # host, so links cannot be rewritten afterwards). None: s3_endpoint_url.
    s3_public_endpoint_url: str | None = None
    s3_region: str = "us-east-1"
    s3_bucket: str = "prismcloud"
    s3_access_key_id: SecretStr | None = None  # None: boto3's usual chain (AWS_* variables, ...)
    s3_secret_access_key: SecretStr | None = None

    readable_buckets: list[str] = Field(default_factory=list, description="For s3:// inputs.")
    fetch_allowed_hosts: list[str] = Field(default_factory=list, description="For https inputs.")
    fetch_allow_private: bool = False  # tests only: lets allow-listed hosts resolve to loopback
    fetch_ca_bundle: str | None = None
    fetch_max_bytes: int = 100 * 2**20
    # Webhook targets (prism_common.outbound.check_webhook_url, applied at submit and delivery).
    webhook_allowed_hosts: list[str] = Field(default_factory=list)
    webhook_allow_http: bool = False  # http:// targets too (a receiver on a trusted network)
    webhook_allow_private: bool = False  # allow-listed hosts may resolve to loopback/private addresses

    upload_max_bytes: int = 100 * 2**20
    # Uploads one API process takes at once (POST /v1/uploads, from the key check to the answer);
    # one more is refused at once with 503 and Retry-After, its body dropped (0: no limit). Each
    # holds a few parts of 8 MiB at most while it streams to the store; without a cap, waiting
    # uploads grew the API's memory with whatever clients sent at once. 32 leaves 8 of the
    # process's 40 threads to the other calls. (Open connections cost up to ~0.3 MB each in
    # uvicorn's buffers besides: uvicorn's --limit-concurrency bounds those.)
    uploads_at_once: int = Field(default=32, ge=0)
    # Any other request body (a job's JSON is read whole before the key is checked); a 5000-item
    # job is about 3 MB.
    request_max_bytes: int = 16 * 2**20
    # POST /v1/stations with the photos to calibrate a station from (multipart: board, plane, a
    # dozen or more calibration photos, plate): PNGs of 1280x1024 are 1-3 MB each, so a dozen pass
    # PRISM_REQUEST_MAX_BYTES. Read after the key check, as uploads; a station.json is held to
    # PRISM_REQUEST_MAX_BYTES.
    station_max_bytes: int = 64 * 2**20
    # Stations calibrated from photos at once by one API process (each decodes its dozen photos,
    # ~60 MB, and takes a second or two of CPU); one more is refused with 503 and Retry-After.
    station_calibrations_at_once: int = Field(default=2, ge=1)
    presign_ttl_s: int = 3600
    max_items_per_job: int = 5000
    max_pixels: int = 50_000_000
    max_frames_per_job: int = 1000  # video frames measured, over all the job's videos
    # Points marked on one frame (points_frame): the most frames one tracking reads, from the
    # first selected frame (or the marked one) to the last; a job over it is refused at submit
    # (or by the worker once `sharpest` has chosen the frames). The frames before the marked one
    # are held in memory (grey, full size) until it is reached: the default holds at most 620 MB
    # of 1920x1080 frames; lower it for larger frames (8.3 MB each at 3840x2160). prism scan's
    # cap is the same 300 (prismcore.video.span.TRACKED_MAX_SPAN).
    tracked_max_span: int = Field(default=300, ge=1)
    # Threads each worker pool process lets OpenCV use. The pool is the worker's parallelism (a
    # process per core, --concurrency); OpenCV's own threads on top of it spent CPU on handing
    # work between threads, not on measuring (benchmarks/service.py on 2 idle cores: the worker
    # 1.45x the engine's CPU a photo with OpenCV's default, a thread per core in each process).
    engine_threads: int = Field(default=1, ge=1)
    tiles_per_face: int = 4
    items_in_flight_per_job: int = 4  # a big batch cannot starve the jobs queued after it
    visibility_timeout_s: int = 300  # a task not acked by then is redelivered (worker lost)
    # A task about an item (plan, tile, finish, frame, frame extraction) that runs this long
    # stops and fails its item (or frame) with the reason; TASK_HARD_MARGIN_S later its process
    # is killed. Keep limit + margin below the visibility timeout, or a slow task is handed out
    # twice before it is stopped.
    task_time_limit_s: float = Field(default=240.0, gt=0)
    task_hard_margin_s: float = Field(default=30.0, gt=0)
    # A video's split stores frames (and with points "auto" searches each) for this long (at
    # most half of task_time_limit_s), then hands the rest to a new task.
    video_split_part_s: float = Field(default=120.0, gt=0)
    public_base_url: str | None = None  # for Location headers behind a proxy
    # The outputs of an item whose spec names no formats (a spec's own list wins), e.g.
    # PRISM_DEFAULT_FORMATS='["laz","glb"]' for compressed LAS and the box model; the metric ones
    # (las, laz, glb, step, drawing) go to items with a scale only, and an item left with none
    # gets csv and ply.
    default_formats: list[OutputFormat] = Field(default_factory=lambda: list(_DEFAULT_FORMATS), min_length=1)
    # The cloud's spacing (mm) for an item in mm (a scale or a station) whose spec names none: one
    # point per voxel of this size (prismcore.scan.spacing). 1 mm is about the sigma of a 1280x1024
    # photo's dimensions (0.8-1.0 mm): the cloud is as fine as the measurement it comes with, at a
    # twentieth of a per-pixel cloud's points (1.9 MB stored a photo, not 24.8 MB: at one point
    # per pixel the outputs and their storage held the service to 0.25 of the engine,
    # docs/explanation/throughput.md). An item's own "spacing_mm": null asks for one point per
    # pixel; PRISM_DEFAULT_SPACING_MM=null makes that every item's default.
    default_spacing_mm: float | None = Field(default=1.0, gt=0)

    @field_validator("webhook_secret")
    @classmethod
    def _webhook_key(cls, secret: SecretStr) -> SecretStr:
        signing_key(secret.get_secret_value())  # a malformed whsec_ secret stops the start
        return secret

    @field_validator("default_spacing_mm", mode="before")
    @classmethod
    def _per_pixel(cls, value: object) -> object:
        # PRISM_DEFAULT_SPACING_MM=null (or empty): one point per pixel, as the engine's default
        return None if isinstance(value, str) and value.strip().lower() in ("", "null", "none") else value

    @field_validator("redis_sentinels", mode="before")
    @classmethod
    def _sentinels(cls, value: object) -> object:
        if isinstance(value, str):
            value = [part.strip() for part in value.split(",") if part.strip()]
        for address in value if isinstance(value, list) else []:
            host, _, port = str(address).rpartition(":")
            if not host or not port.isdigit():
                raise ValueError(f"redis_sentinels: {address!r} is not host:port")
        return value

    @field_validator("fetch_allowed_hosts", "webhook_allowed_hosts")
    @classmethod
    def _hostnames(cls, hosts: list[str]) -> list[str]:
        # URLs' host names are compared lowercased, without the root's trailing dot; the lists
        # are kept the same way, so "Example.COM." allows https://example.com/ as meant.
        return [h.strip().lower().rstrip(".") for h in hosts]

    # Admission: more waiting tasks than this and submit answers 503 + Retry-After (0: no limit).
    queue_max_depth: int = 20_000
    queue_retry_after_s: int = 30
    # Per API key, over every /v1 call, shared by all API processes through Redis (0: no limit).
    # Bursts of up to this many calls pass; past it, calls are let through at this rate.
    rate_limit_per_minute: int = 3000
    # Per client address: past this many refused keys (bursts of as many), every further refused
    # key from the address answers 429 until its budget refills (0: off); a valid key is never
    # locked out by it, so one bad client does not lock out everyone behind its NAT or proxy.
    # Behind a proxy, run uvicorn with --proxy-headers and --forwarded-allow-ips for the address.
    auth_failures_per_minute: int = 30

    # The watchdog (in every worker; one sweep at a time across hosts, through a Redis lock).
    watchdog_interval_s: int = 30
    # A job with no progress and no task of its own waiting or running for this long is
    # restarted where it stopped, `job_stall_restarts` times, then failed with the reason. A
    # waiting or running task keeps a job from looking stalled however long it takes, so this
    # can be short: it is how long a job waits when a worker's death took a message with it.
    job_stall_timeout_s: int = 120
    job_stall_restarts: int = 2
    job_max_age_s: int = 86_400  # any job not final this long after submission fails
    # Uploads (and the frames decoded from a video upload) are deleted this long after they were
    # made or last named by a job, by the watchdog's sweep (0: kept for good). Jobs keep their
    # outputs regardless.
    upload_ttl_s: int = 7 * 86_400
    # Ended jobs (their record and every object under jobs/{id}/) are deleted this long after
    # they were submitted, by the same sweep (0: kept for good, the default: results are the
    # clients' and removing them is the operator's decision).
    job_ttl_s: int = 0

    @model_validator(mode="after")
    def _lifetimes_fit(self) -> Settings:
        for name in ("upload_ttl_s", "job_ttl_s"):
            ttl = getattr(self, name)
            if 0 < ttl < self.job_max_age_s:
                raise ValueError(f"{name}={ttl} is shorter than job_max_age_s={self.job_max_age_s}: "
                                 "a job could outlive it")
        return self


@lru_cache
def get_settings() -> Settings:
    """The process's settings (cached; tests override the FastAPI dependency instead)."""
    return Settings()  # type: ignore[call-arg]  # required fields come from the environment

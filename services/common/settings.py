"""The service's configuration: one pydantic-settings class, read from PRISM_* variables."""

from __future__ import annotations

from functools import lru_cache

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "get_settings"]


class Settings(BaseSettings):
    """Every setting, with its environment variable PRISM_<NAME>.

    Secrets (`api_keys`, `webhook_secret`) have no default: the service refuses to start
    without them.
    """

    model_config = SettingsConfigDict(env_prefix="PRISM_", extra="ignore")

    # Who may call: {"tenant name": "api key"}, e.g. PRISM_API_KEYS='{"acme": "k-..."}'.
    api_keys: dict[str, SecretStr]
    webhook_secret: SecretStr = Field(description="HMAC-SHA256 key for webhook signatures.")

    redis_url: str = "redis://127.0.0.1:6379/0"
    s3_endpoint_url: str | None = None  # None: AWS S3
    s3_region: str = "us-east-1"
    s3_bucket: str = "prismcloud"
    s3_access_key_id: SecretStr | None = None  # None: boto3's usual chain (AWS_* variables, ...)
    s3_secret_access_key: SecretStr | None = None

    readable_buckets: list[str] = Field(default_factory=list, description="For s3:// inputs.")
    fetch_allowed_hosts: list[str] = Field(default_factory=list, description="For https inputs.")
    fetch_allow_private: bool = False  # tests only: lets allow-listed hosts resolve to loopback
    fetch_ca_bundle: str | None = None
    fetch_max_bytes: int = 100 * 2**20
    webhook_allowed_hosts: list[str] = Field(default_factory=list)
    webhook_allow_private: bool = False  # tests only

    upload_max_bytes: int = 100 * 2**20
    presign_ttl_s: int = 3600
    max_items_per_job: int = 5000
    max_pixels: int = 50_000_000
    tiles_per_face: int = 4
    items_in_flight_per_job: int = 4  # a big batch cannot starve the jobs queued after it
    visibility_timeout_s: int = 300  # a task not acked by then is redelivered (worker lost)
    public_base_url: str | None = None  # for Location headers behind a proxy


@lru_cache
def get_settings() -> Settings:
    """The process's settings (cached; tests override the FastAPI dependency instead)."""
    return Settings()  # type: ignore[call-arg]  # required fields come from the environment

"""What the API accepts and answers: the public shapes, separate from the stored records."""

from __future__ import annotations

import math
from datetime import datetime
from typing import Any

from prism_common.records import State
from pydantic import BaseModel, ConfigDict, Field, field_validator

from prismcore.spec import ScanSpec

__all__ = ["DimensionsPublic", "ItemPublic", "JobCreate", "JobList", "JobPublic", "ResultPublic",
           "UploadPublic"]


def _first_non_finite(value: Any, path: str = "") -> str | None:
    """The path of the first NaN/Infinity in parsed JSON, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return path or "value"
    if isinstance(value, dict):
        found = (_first_non_finite(v, f"{path}.{k}" if path else str(k)) for k, v in value.items())
    elif isinstance(value, list | tuple):
        found = (_first_non_finite(v, f"{path}[{i}]") for i, v in enumerate(value))
    else:
        return None
    return next((f for f in found if f is not None), None)


class JobCreate(BaseModel):
    """A batch of scans: each item is the `prism scan --spec` model, images given as references."""

    model_config = ConfigDict(extra="forbid")

    items: list[ScanSpec] = Field(min_length=1, description="The scans, run in order.")
    client_reference: str | None = Field(default=None, max_length=200,
                                         description="Your own id for the batch, echoed back.")
    webhook_url: str | None = Field(default=None, max_length=2000,
                                    description="POSTed the finished job (allow-listed hosts).")

    @field_validator("items", mode="before")
    @classmethod
    def _finite_numbers(cls, items: Any) -> Any:
        # Python's JSON parser accepts NaN/Infinity, and a few spec fields (principal_point) do not
        # check finiteness; stored, they would come back as null and break the record for good.
        if isinstance(items, list):
            for i, item in enumerate(items):
                if (where := _first_non_finite(item)) is not None:
                    raise ValueError(f"item {i}: {where} is not a finite number")
        return items


class DimensionsPublic(BaseModel):
    width: float
    height: float
    depth: float
    unit: str


class ResultPublic(BaseModel):
    points: int
    dimensions: DimensionsPublic
    point_loss: float
    warnings: list[str]


class ItemPublic(BaseModel):
    index: int
    state: State
    error: str | None
    result: ResultPublic | None
    downloads: dict[str, str] = Field(
        default_factory=dict, description="Presigned GET URLs of the outputs: csv, ply, report.")


class JobPublic(BaseModel):
    id: str
    state: State
    progress: int = Field(ge=0, le=100)
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    client_reference: str | None
    webhook_url: str | None
    error: str | None
    items: list[ItemPublic]


class JobList(BaseModel):
    jobs: list[JobPublic]
    next_cursor: str | None = Field(description="Pass as `cursor` for the next page; null at the end.")


class UploadPublic(BaseModel):
    id: str
    reference: str = Field(description="Use as an item's image: `upload:ID`.")
    size: int
    name: str

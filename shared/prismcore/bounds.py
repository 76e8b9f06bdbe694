"""The bounds of every scale and length a spec (or a camera model) gives.

Far outside what a photo of a box can show, a value is a typo or a probe, and one like 1e300
overflows the engine's arithmetic (the item then fails when polled, "points hold ... non-finite
values"); refused by the model, it is a 422 at submit naming the field (the API) or one line
and exit 2 (the CLI). Each bound is in the JSON schema too (`minimum`, `maximum`). Pydantic
only, like `spec`.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, Field

__all__ = ["FOCAL_PX_RANGE", "LENGTH_MM_RANGE", "MM_PER_PX_RANGE", "FocalPx", "MmPerPxValue",
           "NonNegativeMm", "PositiveMm"]

LENGTH_MM_RANGE = (1e-3, 1e6)
"""A length in mm (a known edge, a shooting distance, a nominal size, a spacing): 1 um to 1 km."""
MM_PER_PX_RANGE = (1e-6, 1e3)
"""Millimetres per pixel: 1 nm to 1 m a pixel."""
FOCAL_PX_RANGE = (1.0, 1e6)
"""A focal length in pixels (a 50-megapixel photo through an 800 mm lens is about 2e5 px)."""


def _within(low: float, high: float, unit: str, what: str) -> AfterValidator:
    """A check that the value lies in [low, high], its message quoting the value."""

    def check(value: float) -> float:
        if not low <= value <= high:
            raise ValueError(f"{value:g} {unit} is out of range: {what} is {low:g} to {high:g} {unit}")
        return value

    return AfterValidator(check)


# Zero, negative and non-finite values keep pydantic's own messages (gt/ge, allow_inf_nan); the
# bounds are checked after, quoting the value, and stated in the schema for clients.
PositiveMm = Annotated[float, Field(gt=0.0, allow_inf_nan=False,
                                    json_schema_extra={"minimum": LENGTH_MM_RANGE[0],
                                                       "maximum": LENGTH_MM_RANGE[1]}),
                       _within(*LENGTH_MM_RANGE, "mm", "a length")]
NonNegativeMm = Annotated[float, Field(ge=0.0, allow_inf_nan=False,
                                       json_schema_extra={"maximum": LENGTH_MM_RANGE[1]}),
                          _within(0.0, LENGTH_MM_RANGE[1], "mm", "a tolerance")]
MmPerPxValue = Annotated[float, Field(gt=0.0, allow_inf_nan=False,
                                      json_schema_extra={"minimum": MM_PER_PX_RANGE[0],
                                                         "maximum": MM_PER_PX_RANGE[1]}),
                         _within(*MM_PER_PX_RANGE, "mm/px", "a scale")]
FocalPx = Annotated[float, Field(gt=0.0, allow_inf_nan=False,
                                 json_schema_extra={"minimum": FOCAL_PX_RANGE[0],
                                                    "maximum": FOCAL_PX_RANGE[1]}),
                    _within(*FOCAL_PX_RANGE, "px", "a focal length")]

"""`prism schema`: print the job specification's JSON Schema."""

from __future__ import annotations

import json

from prismcore import ScanSpec

__all__ = ["schema"]


def schema() -> None:
    """Print the JSON Schema of the scan job specification (the --spec file format)."""
    print(json.dumps(ScanSpec.model_json_schema(), indent=2))

"""`prism schema`: print the job specification's JSON Schema."""

from __future__ import annotations

import json

__all__ = ["schema"]


def schema() -> None:
    """Print the JSON Schema of the scan job specification (the --spec file format)."""
    from prismcore.spec import ScanSpec

    print(json.dumps(ScanSpec.model_json_schema(), indent=2))

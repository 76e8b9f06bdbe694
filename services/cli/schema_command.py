"""`prism schema`: print the job specification's JSON Schema (or, with --report, report.json's)."""

from __future__ import annotations

import json
from typing import Annotated

import typer

__all__ = ["schema"]


def schema(
    report: Annotated[bool, typer.Option("--report", help="report.json's JSON Schema instead (the one "
                                         "docs/reference/report.schema.json publishes).")] = False,
) -> None:
    """Print the JSON Schema of the scan job specification (the --spec file format)."""
    if report:
        from prismcore.report import report_schema

        print(json.dumps(report_schema(), indent=2))
        return
    from prismcore.spec import ScanSpec

    print(json.dumps(ScanSpec.model_json_schema(), indent=2))

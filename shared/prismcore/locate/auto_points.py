"""Measuring with the points the zero-click search found (`prismcore.locate.search`): the rules the CLI
and the worker share, so a found box is refused and recorded the same way wherever it is measured.

A found box that the engine then refuses (its fit guards, a face too thin, ...) is the search's
failure, not the person's: the message says so, since nobody clicked the points it names.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from prismcore.errors import InputError
from prismcore.report import FoundPoints, ScanReport
from prismcore.scan.pipeline import ScanResult, run_scan
from prismcore.spec import ScanSpec

__all__ = ["found_box_guard", "record_found", "scan_found"]


@contextmanager
def found_box_guard(auto: bool = True) -> Iterator[None]:
    """Around measuring a spec: with `auto`, an InputError is re-raised as the search's refusal."""
    try:
        yield
    except InputError as exc:
        if not auto:
            raise
        raise InputError(f"points auto: the box found fails the fit guards: {exc}") from None


def record_found(report: ScanReport, found: dict[str, Any]) -> None:
    """Mark `report` as measured with found points.

    `found` is `locate.Found.report()`: its confidence, side face, points and warnings are kept
    under ``auto_points``, and its warnings (a low confidence: check the points) join the scan's.
    """
    auto = FoundPoints.model_validate(found)
    report.points_source = "auto"
    report.auto_points = auto
    report.warnings = [*report.warnings, *auto.warnings]


def scan_found(spec: ScanSpec, found: dict[str, Any] | None, *args: Any, **kwargs: Any) -> ScanResult:
    """`run_scan(spec, *args, **kwargs)` under the found points' rules: with `found` (the
    search's `Found.report()`; None: the points were given) a refusal is the search's and the
    report is marked as measured with found points."""
    with found_box_guard(found is not None):
        result = run_scan(spec, *args, **kwargs)
    if found is not None:
        record_found(result.report, found)
    return result

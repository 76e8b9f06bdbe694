"""prismcore: measured 3D point clouds of box-shaped parts from photos (the pure engine).

No web, queue or storage code lives here: functions take arrays and return arrays.
Names are imported on first use, so `prismcore.spec` (pydantic only) can be used by the
service's API without loading numpy and OpenCV.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

_EXPORTS = {
    "Cloud": "cloud",
    "Dimensions": "measure",
    "InputError": "errors",
    "ReferencePoints": "spec",
    "ScanPlan": "pipeline",
    "ScanResult": "pipeline",
    "ScanSpec": "spec",
    "finish_scan": "pipeline",
    "parse_points": "spec",
    "plan_scan": "pipeline",
    "run_scan": "pipeline",
    "scan_face": "pipeline",
}

__all__ = [
    "Cloud",
    "Dimensions",
    "InputError",
    "ReferencePoints",
    "ScanPlan",
    "ScanResult",
    "ScanSpec",
    "__version__",
    "finish_scan",
    "parse_points",
    "plan_scan",
    "run_scan",
    "scan_face",
]

if TYPE_CHECKING:
    from .cloud import Cloud
    from .errors import InputError
    from .measure import Dimensions
    from .pipeline import ScanPlan, ScanResult, finish_scan, plan_scan, run_scan, scan_face
    from .spec import ReferencePoints, ScanSpec, parse_points


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""The paper's scan: real dimensions from the fitted faces, the colour scan over row tiles, the
cloud's assembly and spacing, and the pipeline that chains them (plan, tiles, finish).

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "Cloud",
    "Dimensions",
    "FacePlan",
    "FaceScan",
    "ScanPlan",
    "ScanResult",
    "assemble",
    "finish_scan",
    "measure_affine",
    "measure_perspective",
    "plan_scan",
    "run_scan",
    "scan_band",
    "scan_face",
    "thin_to_count",
    "thin_to_spacing",
]

_EXPORTS = {
    "Cloud": "cloud",
    "Dimensions": "measure",
    "FacePlan": "colour_scan",
    "FaceScan": "colour_scan",
    "ScanPlan": "pipeline",
    "ScanResult": "pipeline",
    "assemble": "cloud",
    "finish_scan": "pipeline",
    "measure_affine": "measure",
    "measure_perspective": "measure",
    "plan_scan": "pipeline",
    "run_scan": "pipeline",
    "scan_band": "colour_scan",
    "scan_face": "pipeline",
    "thin_to_count": "spacing",
    "thin_to_spacing": "spacing",
}

if TYPE_CHECKING:
    from prismcore.scan.cloud import Cloud, assemble
    from prismcore.scan.colour_scan import FacePlan, FaceScan, scan_band
    from prismcore.scan.measure import Dimensions, measure_affine, measure_perspective
    from prismcore.scan.pipeline import ScanPlan, ScanResult, finish_scan, plan_scan, run_scan, scan_face
    from prismcore.scan.spacing import thin_to_count, thin_to_spacing

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

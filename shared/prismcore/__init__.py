"""prismcore: measured 3D point clouds of box-shaped parts from photos (the pure engine).

No web, queue or storage code lives here: functions take arrays and return arrays.
"""

__version__ = "0.1.0"

from .cloud import Cloud
from .errors import InputError
from .measure import Dimensions
from .pipeline import ScanPlan, ScanResult, finish_scan, plan_scan, run_scan, scan_face
from .spec import ReferencePoints, ScanSpec, parse_points

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

"""prismcore: measured 3D point clouds of box-shaped parts from photos (the pure engine).

No web, queue or storage code lives here: functions take arrays and return arrays. The
contract callers hand the engine is top-level (`spec`, `camera`, `bounds`, `errors`); the
engine is in subpackages by stage, each naming its public API in its ``__init__``:

``io``         photos, EXIF, videos' frames, containers
``geometry``   faces, edges, perspective fits, rounded edges, chessboard calibration
``quality``    verdicts against tolerances
``scan``       dimensions, the colour scan, the cloud, the pipeline
``locate``     the zero-click search
``multiview``  several views as one box
``video``      frame selection, search along a video, focal pooling, summary
``outputs``    CSV, PLY, LAS/LAZ, glb, the overlay
``station``    a camera calibrated to the support: no clicks, no known edge

Names are imported on first use, so `prismcore.spec` (pydantic only) can be used by the
service's API without loading numpy and OpenCV. docs/explanation/architecture.md draws the layers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports
from prismcore._version import __version__

_EXPORTS = {
    "CameraModel": "camera",
    "Cloud": "scan.cloud",
    "Dimensions": "scan.measure",
    "InputError": "errors",
    "ReferencePoints": "spec",
    "ScanPlan": "scan.pipeline",
    "ScanResult": "scan.pipeline",
    "ScanSpec": "spec",
    "Station": "station.calibrate",
    "find_points": "locate.search",
    "finish_scan": "scan.pipeline",
    "fit_views": "multiview.joint",
    "load_image": "io.images",
    "parse_points": "spec",
    "plan_scan": "scan.pipeline",
    "run_scan": "scan.pipeline",
    "scan_face": "scan.pipeline",
    "write_csv": "outputs.writers",
    "write_ply": "outputs.writers",
}

__all__ = [
    "CameraModel",
    "Cloud",
    "Dimensions",
    "InputError",
    "ReferencePoints",
    "ScanPlan",
    "ScanResult",
    "ScanSpec",
    "Station",
    "__version__",
    "find_points",
    "finish_scan",
    "fit_views",
    "load_image",
    "parse_points",
    "plan_scan",
    "run_scan",
    "scan_face",
    "write_csv",
    "write_ply",
]

if TYPE_CHECKING:
    from prismcore.camera import CameraModel
    from prismcore.errors import InputError
    from prismcore.io.images import load_image
    from prismcore.locate.search import find_points
    from prismcore.multiview.joint import fit_views
    from prismcore.outputs.writers import write_csv, write_ply
    from prismcore.scan.cloud import Cloud
    from prismcore.scan.measure import Dimensions
    from prismcore.scan.pipeline import ScanPlan, ScanResult, finish_scan, plan_scan, run_scan, scan_face
    from prismcore.spec import ReferencePoints, ScanSpec, parse_points
    from prismcore.station.calibrate import Station

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

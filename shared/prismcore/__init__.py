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

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

"""What a scan writes: CSV and PLY clouds, LAS/LAZ, a glTF box model, the overlay picture, and the
part as a STEP solid and an inspection drawing (SVG, PDF, DXF).

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

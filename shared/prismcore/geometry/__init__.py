"""The geometry of a box in a photo: face quadrilaterals from the points, sub-pixel edges, pinhole
fits of a rectangle or a box (focal length, distortion), rounded edges, chessboard calibration.

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

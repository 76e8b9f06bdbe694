"""Videos: which frames to measure, the zero-click search along them, one focal length pooled
over a camera's frames, and the summary of a video's measurements.

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

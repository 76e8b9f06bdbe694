"""Reading inputs: photos (decoded safely to RGB), their EXIF focal length, videos' frames, and
which container a file is, from its first bytes.

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

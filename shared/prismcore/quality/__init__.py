"""Quality control: each measured dimension against its nominal size and tolerance.

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

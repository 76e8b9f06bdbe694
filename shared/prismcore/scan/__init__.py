"""The paper's scan: real dimensions from the fitted faces, the colour scan over row tiles, the
cloud's assembly and spacing, and the pipeline that chains them (plan, tiles, finish).

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)

"""The face of `prismcore.locate`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .auto_points import found_box_guard as found_box_guard
from .auto_points import record_found as record_found
from .auto_points import scan_found as scan_found
from .search import Found as Found
from .search import find_points as find_points
from .search import resolve_points as resolve_points

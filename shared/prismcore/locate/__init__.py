"""Zero-click: a box found in a photo, its faces and its seven reference points, and what
measuring found points adds.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "Found",
    "find_points",
    "found_box_guard",
    "record_found",
    "resolve_points",
    "scan_found",
]

_EXPORTS = {
    "Found": "search",
    "find_points": "search",
    "found_box_guard": "auto_points",
    "record_found": "auto_points",
    "resolve_points": "search",
    "scan_found": "auto_points",
}

if TYPE_CHECKING:
    from prismcore.locate.auto_points import found_box_guard, record_found, scan_found
    from prismcore.locate.search import Found, find_points, resolve_points

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

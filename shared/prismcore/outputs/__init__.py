"""What a scan writes: CSV and PLY clouds, LAS/LAZ, a glTF box model and the overlay picture.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "box_glb",
    "draw_overlay",
    "overlay_from_report",
    "write_csv",
    "write_format",
    "write_las",
    "write_ply",
]

_EXPORTS = {
    "box_glb": "glb",
    "draw_overlay": "overlay",
    "overlay_from_report": "overlay_report",
    "write_csv": "writers",
    "write_format": "writers",
    "write_las": "las",
    "write_ply": "writers",
}

if TYPE_CHECKING:
    from prismcore.outputs.glb import box_glb
    from prismcore.outputs.las import write_las
    from prismcore.outputs.overlay import draw_overlay
    from prismcore.outputs.overlay_report import overlay_from_report
    from prismcore.outputs.writers import write_csv, write_format, write_ply

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

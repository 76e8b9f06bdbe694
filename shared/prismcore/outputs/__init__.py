"""What a scan writes: CSV and PLY clouds, LAS/LAZ, a glTF box model, the overlay picture, and the
part as a STEP solid and an inspection drawing (SVG, PDF, DXF).

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "Part",
    "box_glb",
    "draw_overlay",
    "drawing_dxf",
    "drawing_pdf",
    "drawing_svg",
    "inspection_sheet",
    "overlay_from_report",
    "part_from_report",
    "step_bytes",
    "step_metadata",
    "write_csv",
    "write_format",
    "write_las",
    "write_part",
    "write_ply",
]

_EXPORTS = {
    "Part": "part",
    "box_glb": "glb",
    "draw_overlay": "overlay",
    "drawing_dxf": "drawing_files",
    "drawing_pdf": "drawing_files",
    "drawing_svg": "drawing_files",
    "inspection_sheet": "drawing",
    "overlay_from_report": "overlay_report",
    "part_from_report": "part",
    "step_bytes": "step",
    "step_metadata": "step",
    "write_csv": "writers",
    "write_format": "writers",
    "write_las": "las",
    "write_part": "writers",
    "write_ply": "writers",
}

if TYPE_CHECKING:
    from prismcore.outputs.drawing import inspection_sheet
    from prismcore.outputs.drawing_files import drawing_dxf, drawing_pdf, drawing_svg
    from prismcore.outputs.glb import box_glb
    from prismcore.outputs.las import write_las
    from prismcore.outputs.overlay import draw_overlay
    from prismcore.outputs.overlay_report import overlay_from_report
    from prismcore.outputs.part import Part, part_from_report
    from prismcore.outputs.step import step_bytes, step_metadata
    from prismcore.outputs.writers import write_csv, write_format, write_part, write_ply

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

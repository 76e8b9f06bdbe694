"""Several photos of one part (or frames of one video) measured as ONE box, and its joint.json.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "JointResult",
    "View",
    "fit_views",
    "joint_report",
]

_EXPORTS = {
    "JointResult": "joint",
    "View": "views",
    "fit_views": "joint",
    "joint_report": "report",
}

if TYPE_CHECKING:
    from prismcore.multiview.joint import JointResult, fit_views
    from prismcore.multiview.report import joint_report
    from prismcore.multiview.views import View

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

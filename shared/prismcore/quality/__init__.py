"""Quality control: each measured dimension against its nominal size and tolerance.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "DimensionVerdict",
    "Verdict",
    "judge",
    "quality_block",
    "quality_from_report",
]

_EXPORTS = {
    "DimensionVerdict": "verdicts",
    "Verdict": "verdicts",
    "judge": "verdicts",
    "quality_block": "verdicts",
    "quality_from_report": "verdicts",
}

if TYPE_CHECKING:
    from prismcore.quality.verdicts import (
        DimensionVerdict,
        Verdict,
        judge,
        quality_block,
        quality_from_report,
    )

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

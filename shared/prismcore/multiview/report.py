"""joint.json: the report of several views measured as ONE box (`prismcore.multiview.joint.fit_views`), the
same document for `prism scan A B --points-file` and for a service item (views, or a video's
frames with fit "joint")."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from prismcore.multiview.joint import JointResult

__all__ = ["joint_report"]

_DIMENSIONS = ("width", "height", "depth")


def joint_report(result: JointResult, labels: Sequence[int] | None = None) -> dict[str, Any]:
    """The dimensions with their sigma, the camera, each view used and each left out with the reason.

    labels : each input view's index as the caller numbers it (a video's frame indices); the
        views' positions (0, 1, ...) when None.
    """
    d = result.dimensions
    assert d.uncertainty is not None
    n = len(result.views) + len(result.left_out)
    gone = {o.index for o in result.left_out}
    used = [k for k in range(n) if k not in gone]  # `views` are the used ones, in input order

    def label(k: int) -> int:
        return k if labels is None else int(labels[k])

    return {
        "dimensions": {**{a: round(getattr(d, a), 4) for a in _DIMENSIONS}, "unit": d.unit},
        "uncertainty": dict(zip(_DIMENSIONS, (round(s, 4) for s in d.uncertainty), strict=True)),
        "camera": {"focal_px": round(result.focal_px, 3),
                   "focal_std_px": None if result.focal_std_px is None else round(result.focal_std_px, 3),
                   "distortion_kappa": result.distortion.kappa},
        "views": [{"index": label(k), "name": v.name, "click_rms_px": round(v.click_rms_px, 3),
                   "line_rms_px": round(v.line_rms_px, 3),
                   "alone": {a: round(getattr(v.single, a), 4) for a in _DIMENSIONS},
                   "disagreement": None if v.disagreement is None else round(v.disagreement, 3),
                   "lines_left_out": v.lines_left_out}
                  for k, v in zip(used, result.views, strict=True)],
        "left_out": [{"index": label(o.index), "name": o.name, "reason": o.reason} for o in result.left_out],
        "warnings": list(result.warnings) + list(d.notes),
    }

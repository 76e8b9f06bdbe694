"""The views of a joint fit: one photo (or frame) and its seven points as given (`View`), and each
view measured alone by the single-view pipeline, its evidence made ready for the joint fit
(`_prepare`; on request without the edge lines its clicks disagree with).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from prismcore.errors import InputError
from prismcore.geometry.box_model import SECOND_FACES
from prismcore.geometry.faces import clicked_quads
from prismcore.geometry.perspective import (
    SIGMA_CLICK_PX,
    SIGMA_LINE_PX,
    FaceEvidence,
)
from prismcore.scan.measure import Dimensions
from prismcore.spec import KnownEdge, ReferencePoints, ScanSpec

__all__ = ["View"]


@dataclass(frozen=True)
class View:
    """One photo of the part and the seven points clicked on it.

    image : ndarray, shape (H, W, 3)
        RGB, uint8 (or float32 0-255).
    points : ReferencePoints or sequence of seven (x, y)
        P1..P7 in the engine's order, image px.
    side_face : {"auto", "right", "left", "top"}
        Which face P4, P5, P7 mark (as `ScanSpec.side_face`).
    name : str
        How the view is named in the result (a file name, "frame 127"); "view k" when empty.
    """

    image: np.ndarray
    points: ReferencePoints | Sequence[Sequence[float]]
    side_face: str = "auto"
    name: str = ""


@dataclass(frozen=True)
class _Prepared:
    """A view measured alone, its evidence ready for the joint fit (distortion not yet removed)."""

    index: int
    name: str
    side_face: str
    front: FaceEvidence
    side: FaceEvidence
    single: Dimensions
    focal_px: float | None
    image: np.ndarray
    edges_dropped: int = 0
    lines_rejected: int = 0
    line_sigma_px: float = SIGMA_LINE_PX
    click_sigma_px: float = SIGMA_CLICK_PX
    # The faces' evidence undistorted, per face and lens (`problem._terms`); shared by the views
    # `replace` makes of this one, whose faces are either these (same answer) or new (own key).
    undistorted: dict[tuple[int, float, bytes], tuple[FaceEvidence, FaceEvidence]] = field(
        default_factory=dict, compare=False, repr=False)

    def without_lines(self, drop: dict[str, set[int]] | None = None) -> _Prepared:
        """The view with the named sides' edge lines (all, when None) taken out (its clicks stay)."""
        faces = []
        for name in ("front", "side"):
            face: FaceEvidence = getattr(self, name)
            gone = set(range(4)) if drop is None else drop.get(name, set())
            lines = tuple(None if s in gone else line for s, line in enumerate(face.lines))
            samples = tuple(None if s in gone else e for s, e in enumerate(face.samples))
            faces.append(FaceEvidence(face.corners, face.clicked, lines, samples))
        n = 0 if drop is None else sum(len(v) for v in drop.values())
        return replace(self, front=faces[0], side=faces[1], edges_dropped=self.edges_dropped + n)


def _prepare(k: int, view: View, scale: KnownEdge, focal_px: float | None,
             edge_agree_px: float | None = None) -> _Prepared:
    from prismcore.scan.pipeline import plan_scan

    name = view.name or f"view {k + 1}"
    points = view.points if isinstance(view.points, ReferencePoints) else [list(map(float, p))
                                                                           for p in view.points]
    spec = ScanSpec.model_validate({"image": name if "." in name else f"{name}.png", "points": points,
                                    "side_face": view.side_face, "scale": scale, "focal_px": focal_px})
    plan = plan_scan(spec, view.image, click_noise_rules=False)  # the joint fit weighs the lines
    if not plan.dimensions.perspective:
        raise InputError(f"{name}: the box was not fitted in perspective (all seven points are needed)")
    assert spec.points is not None
    face = plan.side_face
    marked = clicked_quads(spec.points, two_photo=False, side_face=face)
    evidence = [FaceEvidence(plan.faces[i].region, getattr(marked, n),
                             tuple(f.line if f.fitted else None for f in plan.edges[n]),
                             tuple(f.points if f.fitted else None for f in plan.edges[n]))
                for i, n in enumerate(("front", "side"))]
    fitted = plan.camera.get("focal_px")
    prepared = _Prepared(k, name, face, evidence[0], evidence[1], plan.dimensions,
                         float(fitted) if fitted is not None else None, view.image)
    return prepared if edge_agree_px is None else _agreeing(prepared, edge_agree_px)


def _agreeing(view: _Prepared, limit_px: float) -> _Prepared:
    """The view without the refined edge lines its clicks disagree with: a side's line is dropped
    when the two clicked corners at its ends lie farther than `limit_px` from it (mean distance)."""
    drop: dict[str, set[int]] = {}
    for name, sides in (("front", (0, 1, 2, 3)), ("side", SECOND_FACES[view.side_face].sides)):
        face: FaceEvidence = getattr(view, name)
        for s in sides:
            line = face.lines[s]
            if line is None:
                continue
            ends = face.clicked[[s, (s + 1) % 4]]
            if float(np.abs(ends @ line[:2] + line[2]).mean()) > limit_px:
                drop.setdefault(name, set()).add(s)
    return view.without_lines(drop) if drop else view

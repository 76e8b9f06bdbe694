"""What each side of a face rests on, the refined edge or the click, and why (report and overlay).

A side rests on the click where no edge was found near it; on the refined edge where one was,
unless the whole fit gave the edges up (`scan.fit.unless_snapped`: the box they fit moved the
clicks more than their noise explains, or measures another size than the clicks' own box).

Rules per edge tried and left out, measured with `benchmarks/real_clicks.py` on YCB-Video's real
frames and the photo-like renders: the edge seen near both ends of its side, one colour step
along it, its offset from the clicked side within 3 click sigmas, and no other edge outside it on
the outline (a printed border is not the outline). Each refused some true edges of the renders
(the outermost rule: the worst photo-like error 3.3 % -> 15.4 %), and a box fitted to edges on
some sides and clicks on the others was farther from the truth than either alone (the real
frames' true corners: median 0.05 % -> 2.2 %, worst 0.1 % -> 12 %).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from prismcore.geometry.edges import EdgeFit, line_through

__all__ = ["EdgeUse", "clicked_fit", "judge_edge"]


@dataclass(frozen=True)
class EdgeUse:
    """What one side of a face rests on: the refined edge or the click, and why."""

    source: Literal["edge", "click"]
    reason: str

    def as_json(self) -> dict[str, str]:
        """report.json's form."""
        return {"used": self.source, "why": self.reason}


def judge_edge(fit: EdgeFit, *, outline: bool) -> EdgeUse:
    """What a side rests on before the whole fit's check: its refined edge where one was found.

    Parameters
    ----------
    fit : EdgeFit
        The refined edge (`edges.fit_edge`).
    outline : bool
        The side is on the box's outline (background beyond it), not the fold two faces share.

    Returns
    -------
    EdgeUse
        "edge" (the outline or the fold) when the edge was found, else "click".
    """
    if not fit.fitted:
        return EdgeUse("click", "no clear edge near the clicked side")
    return EdgeUse(
        "edge", "the outline found near the clicks" if outline else "the fold found near the clicks"
    )


def clicked_fit(p: np.ndarray, q: np.ndarray, fit: EdgeFit) -> EdgeFit:
    """The clicked side as an unfitted EdgeFit (what the fit reads as "no edge": the clicks)."""
    return EdgeFit(line_through(p, q), fit.support, fit.rms_px, False)

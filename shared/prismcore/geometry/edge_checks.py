"""Whether a refined edge is clearly the box's outline or fold, or the click should stand.

`edges.fit_edge` takes the line most profiles near a clicked side support. On renders that is the
box's edge; on a real photo it can be a printed border or a label just inside the outline (a real
gelatin box: the red border inside its white outline, +27 % on its height). So a fitted edge on
the outline (a side with only background beyond it) is used only when no other line as well
supported lies outside it within the search band: the outline is the outermost edge, a printed
border is not. Otherwise the clicked side is used, and `EdgeUse.reason` says why, for the report
and the overlay.

Rules tried and left out, measured on the photo-like renders and YCB-Video's real frames
(`benchmarks/real_clicks.py`): the edge seen near both ends of the side, one colour step along
it, and its offset from the clicked side within 3 click sigmas. Each refused some true edges,
and a box fitted to the edges kept on some sides and the clicks on the others was further from
the truth than either alone (real frames: the median 0.05 % -> 2.2 % on the true corners). What
keeps a good click from being moved is the whole fit's test, `scan.fit.unless_snapped`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from prismcore.geometry.edges import Bound, EdgeFit, fit_edge, inward, line_through

__all__ = ["OUTER_REASON", "OUTER_SUPPORT", "EdgeUse", "clicked_fit", "judge_edge"]

OUTER_SUPPORT = 0.6  # a line outside the outline this well supported makes the fitted one inner
_OUTER_GAP_PX = 1.5  # a line outside must be this far out to be another line
OUTER_REASON = "another edge lies outside the one found (a printed border?)"


@dataclass(frozen=True)
class EdgeUse:
    """What one side of a face rests on: the refined edge or the click, and why."""

    source: Literal["edge", "click"]
    reason: str

    def as_json(self) -> dict[str, str]:
        """report.json's form."""
        return {"used": self.source, "why": self.reason}


def _outer_line(
    image: np.ndarray,
    p: np.ndarray,
    q: np.ndarray,
    fit: EdgeFit,
    inside: np.ndarray,
    search_px: float,
    bounds: tuple[Bound, ...],
) -> EdgeFit | None:
    """A line as well supported outside the fitted one (beyond _OUTER_GAP_PX), if there is one."""
    out = -inward(fit.line, inside)  # positive outside the face
    found = fit_edge(image, p, q, search_px=search_px, bounds=(*bounds, (out, _OUTER_GAP_PX)))
    if found.fitted and found.support >= OUTER_SUPPORT:
        return found
    return None


def judge_edge(
    image: np.ndarray,
    p: np.ndarray,
    q: np.ndarray,
    fit: EdgeFit,
    *,
    inside: np.ndarray,
    search_px: float,
    bounds: tuple[Bound, ...],
    outline: bool,
) -> EdgeUse:
    """Whether the refined edge `fit` of the clicked side p -> q is clearly the box's.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
    p, q : ndarray, shape (2,)
        The clicked side's ends, image (x, y) px.
    fit : EdgeFit
        The refined edge (`edges.fit_edge`).
    inside : ndarray, shape (2,)
        A point inside the face (its centre).
    search_px, bounds
        The search the edge was fitted with (the outline test searches the same band).
    outline : bool
        The side is on the box's outline (background beyond it), not the fold two faces share.

    Returns
    -------
    EdgeUse
        "edge" when the photo shows it clearly, else "click" with the reason.
    """
    if not fit.fitted:
        return EdgeUse("click", "no clear edge near the clicked side")
    if outline and _outer_line(image, p, q, fit, inside, search_px, bounds) is not None:
        return EdgeUse("click", OUTER_REASON)
    if outline:
        return EdgeUse("edge", "the outline: no other edge outside it")
    return EdgeUse("edge", "the fold between the faces")


def clicked_fit(p: np.ndarray, q: np.ndarray, fit: EdgeFit) -> EdgeFit:
    """The clicked side as an unfitted EdgeFit (what the fit reads as "no edge": the clicks)."""
    return EdgeFit(line_through(p, q), fit.support, fit.rms_px, False)

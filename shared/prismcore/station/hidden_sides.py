"""A second reading of the part's height for sides the outline lost: where the support's pattern
is hidden below the part's top.

A face that mirrors the support (machined metal), or matches its colour, differs from the plate
too little for the outline to find it, and the box fitted to what was found is the top alone, or
a low box under it: its height reads short (path-traced steel and aluminium: 30-100 % short) and
its sigma, the outline's own, says nothing of it. But such a face still hides the support behind
it: where the plate has a pattern (the board's squares, a table's grain), the photo no longer
shows it there. So the top face as fitted is held where the photo shows it and the box under it is
grown, height by height (the top's corners pushed back along their rays onto the plane at that
height): the band the sides would cover is scored, +1 per pixel that differs from the plate or
hides its pattern, -1 per pixel that shows the plate's pattern unchanged (the support, or a
shadow: a shadow scales the pattern, it does not hide it), a little less than nothing where the
support has no pattern to judge. The height whose band scores best is the second reading.

It is coarse (development renders: 10-30 % off), and is used only where the outline's own reading
is suspect: to widen the sigma by the two readings' gap, or, where the outline gave no height at
all, as the measurement, with its sigma from the score's plateau.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from prismcore.station.boxfit import OutlineFit, project
from prismcore.station.photometry import pattern_match, toned
from prismcore.station.segment import _AT_WHITE, SHADOW_RANGE, _residual

__all__ = ["HiddenSides", "evidence_enough", "read_hidden_sides", "widened"]

_WINDOW = 15  # px: the pattern is compared over windows this wide (a noisy dark face needs many px)
_HIDDEN_NCC = 0.5  # a window correlating less than this with the plate's pattern hides it
_NO_PATTERN = -0.1  # the score of a pixel where the support has no pattern and the photo does not differ
_STEPS = 96  # heights tried
_MARGIN_PX = 24
_PLATEAU = 0.9  # heights whose band scores within this share of the best are as good a reading
_COARSE_SHARE = 0.3  # the reading's own error, of the height (development renders: 10-30 %)
_MIN_EVIDENCE = 0.3  # the mean score of the band added over the outline's height, to take it as the part's


@dataclass(frozen=True)
class HiddenSides:
    """The height read from where the support's pattern is hidden under the part's top.

    height_mm : the best-scoring height. low_mm, high_mm : the heights scoring within _PLATEAU of
    it, or within _COARSE_SHARE / 2 of it, whichever reach further (the reading's spread).
    evidence : the mean score of the band between the outline's height
    and `height_mm` (1: all of it hides the support, -1: all of it shows the support).
    length_mm, width_mm : the footprint under the top at `height_mm` (the top's corners pushed
    back along their rays).
    params, low, high : (6,) float64, the boxes at `height_mm`, `low_mm` and `high_mm` as
    `OutlineFit.params` (x, y mm, yaw rad, log length, log width, log height).
    """

    height_mm: float
    low_mm: float
    high_mm: float
    evidence: float
    length_mm: float
    width_mm: float
    params: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def spread_mm(self) -> tuple[float, float, float]:
        """How far length, width and height differ between the plateau's ends, mm."""
        a, b = np.exp(self.low[3:]), np.exp(self.high[3:])
        return (float(abs(b[0] - a[0])), float(abs(b[1] - a[1])), float(abs(b[2] - a[2])))


def _on_plane(px: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, z: float) -> np.ndarray:
    """Image points (N, 2) px pushed along their rays onto the board-frame plane z (mm): (N, 3)."""
    centre = -R.T @ t
    rays = (R.T @ np.linalg.inv(K) @ np.column_stack([px, np.ones(len(px))]).T).T
    out: np.ndarray = centre + ((z - centre[2]) / rays[:, 2])[:, None] * rays
    return out


def _box_under(top_px: np.ndarray, height: float, K: np.ndarray, R: np.ndarray, t: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The box under a top seen at `top_px` (4, 2) standing `height` mm: its params (6,) and its
    silhouette's corners in the image (8, 2) px. The board's z points into the support."""
    top = _on_plane(top_px, K, R, t, -height)
    a, b = top[1] - top[0], top[3] - top[0]
    length = (np.linalg.norm(a) + np.linalg.norm(top[2] - top[3])) / 2
    width = (np.linalg.norm(b) + np.linalg.norm(top[2] - top[1])) / 2
    centre = top[:, :2].mean(axis=0)
    yaw = float(np.arctan2(a[1] + (top[2] - top[3])[1], a[0] + (top[2] - top[3])[0]))
    with np.errstate(divide="ignore"):  # a fit that gave no height: log 0 is its -inf, as the fit's
        params = np.array([centre[0], centre[1], yaw, np.log(length), np.log(width), np.log(height)])
    foot = top.copy()
    foot[:, 2] = 0.0
    return params, np.vstack([top_px, project(foot, K, R, t)])


def read_hidden_sides(photo_u: np.ndarray, plate_u: np.ndarray, homography: np.ndarray, tone: np.ndarray,
                      shadow_least: float, fit: OutlineFit, K: np.ndarray, R: np.ndarray, t: np.ndarray
                      ) -> HiddenSides | None:
    """The part's height read under `fit`'s top from where the support's pattern is hidden.

    photo_u, plate_u : undistorted RGB (H, W, 3) uint8; homography : plate -> photo pixels; tone :
    (3, 256) the camera's tone change since the plate (`Silhouette.tone`); shadow_least : the
    deepest shadow's scale (`Silhouette.shadow_least`). K (3, 3), R (3, 3), t (3,) mm: the support's
    pose. Heights from `fit`'s to it plus the footprint's longer side are tried, below nine tenths
    of the camera's height over the support; the band is scored where it lies in the photo. None
    where the fit or its grown box is not finite, the crop in the photo is under two windows wide,
    or no height scores above the outline's.
    """
    h, w = photo_u.shape[:2]
    top_px = project(fit.corners()[4:], K, R, t)
    h0 = fit.height_mm
    # no taller than the camera stands above the support: a top beyond it is behind the camera
    below_camera = 0.9 * float(-(-R.T @ t)[2])
    heights = h0 + np.linspace(0.0, max(fit.length_mm, fit.width_mm), _STEPS + 1)
    heights = heights[heights < below_camera]
    if heights.size < 2 or not np.all(np.isfinite(top_px)):
        return None
    tallest = _box_under(top_px, float(heights[-1]), K, R, t)[1]
    if not np.all(np.isfinite(tallest)):
        return None
    x0, y0 = np.floor(np.vstack([top_px, tallest]).min(axis=0)).astype(int) - _MARGIN_PX
    x1, y1 = np.ceil(np.vstack([top_px, tallest]).max(axis=0)).astype(int) + _MARGIN_PX
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
    if x1 - x0 < 2 * _WINDOW or y1 - y0 < 2 * _WINDOW:
        return None
    shift = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1.0]])
    P = photo_u[y0:y1, x0:x1].astype(np.float32)
    bg8 = cv2.warpPerspective(plate_u, shift @ homography, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
    bg = toned(bg8, tone)
    resid = _residual(P, bg, shadow=(shadow_least, SHADOW_RANGE[1]), clipped=bg8 >= _AT_WHITE)
    offset = np.array([x0, y0], np.float64)
    outside = np.ones(resid.shape, np.uint8)
    reach = cv2.convexHull((tallest - offset).astype(np.float32))
    cv2.fillConvexPoly(outside, np.round(reach).astype(np.int32), 0)
    rest = resid[outside > 0]
    noise = float(np.median(rest if rest.size > 100 else resid)) * 1.4826 + 1.0
    differs = resid > max(6.0, 2.5 * noise)
    match = pattern_match(P, bg, _WINDOW)
    hidden = match.structured & (match.ncc < _HIDDEN_NCC)
    score = np.full(resid.shape, _NO_PATTERN, np.float32)
    score[match.structured & ~hidden & ~differs] = -1.0
    score[differs | hidden] = 1.0
    top_mask = np.zeros(resid.shape, np.uint8)
    cv2.fillConvexPoly(top_mask, np.round(top_px - offset).astype(np.int32), 1)
    score[top_mask > 0] = 0.0  # the top is common to every height: only the band under it counts
    under = (top_mask == 0).astype(np.int32)
    crop_h, crop_w = y1 - y0, x1 - x0
    totals, areas, boxes = [], [], []
    for height in heights:
        params, corners = _box_under(top_px, float(height), K, R, t)
        hull = np.round(cv2.convexHull((corners - offset).astype(np.float32))).astype(np.int32)
        # filled within the hull's own rectangle, not the whole crop (a large part's crop is big)
        bx, by, bw, bh = cv2.boundingRect(hull)
        x, y = max(0, bx), max(0, by)
        bw, bh = min(bx + bw, crop_w) - x, min(by + bh, crop_h) - y
        band = np.zeros((max(bh, 0), max(bw, 0)), np.uint8)
        if band.size:
            cv2.fillConvexPoly(band, hull - np.array([x, y], np.int32), 1)
        inside = band > 0
        totals.append(float(score[y:y + bh, x:x + bw][inside].sum()))
        areas.append(int(under[y:y + bh, x:x + bw][inside].sum()))
        boxes.append(params)
    best = int(np.argmax(totals))
    if best == 0 or totals[best] <= totals[0]:
        return None
    good = np.nonzero(np.asarray(totals) >= totals[0] + _PLATEAU * (totals[best] - totals[0]))[0]
    added = max(areas[best] - areas[0], 1)
    params = boxes[best]
    # the reading's spread: the plateau's, or its own coarseness, whichever is wider (the
    # footprint under the top follows the height along the rays)
    low = min(float(heights[good.min()]), (1 - _COARSE_SHARE / 2) * float(heights[best]))
    high = max(float(heights[good.max()]), (1 + _COARSE_SHARE / 2) * float(heights[best]))
    return HiddenSides(
        height_mm=float(heights[best]), low_mm=low, high_mm=high,
        evidence=(totals[best] - totals[0]) / added, length_mm=float(np.exp(params[3])),
        width_mm=float(np.exp(params[4])), params=params, low=_box_under(top_px, low, K, R, t)[0],
        high=_box_under(top_px, high, K, R, t)[0])


def evidence_enough(reading: HiddenSides) -> bool:
    """Whether the band the reading adds under the top is mostly the part's (its mean score)."""
    return reading.evidence >= _MIN_EVIDENCE


def widened(fit: OutlineFit, reading: HiddenSides, *, adopt: bool) -> tuple[OutlineFit, str]:
    """`fit` with the second reading taken in, and the warning that says so.

    adopt : the outline gave no height (a box too flat to be one): the reading's box is the
    measurement, its sizes' sigma half of their spread between the reading's low and high ends.
    Else the outline's box is kept and the two readings' gap is taken as a
    rival's (`OutlineFit.ambiguity_mm`: the sigma covers half of it).
    """
    size = np.exp(reading.params[3:])
    if adopt:
        cov = fit.cov.copy()  # the top's own outline still places length and width; no height
        cov[5, :] = 0.0
        cov[:, 5] = 0.0
        rivals = tuple(float(max(a, b)) for a, b in zip(fit.ambiguity_mm, reading.spread_mm(), strict=True))
        return replace(fit, params=reading.params, cov=cov, ambiguity_mm=(rivals[0], rivals[1], rivals[2])), (
            "only the part's top was outlined (its sides mirror the support or match its colour): its "
            f"height, {reading.height_mm:.1f} mm, was read from where the support's pattern is hidden "
            f"below the top (between {reading.low_mm:.1f} and {reading.high_mm:.1f} mm): a coarse reading; "
            "light the part from another side, or put a mat of another colour under it")
    own = np.array([fit.length_mm, fit.width_mm, fit.height_mm])
    gap = np.abs(size - own)
    amb = tuple(float(max(a, g)) for a, g in zip(fit.ambiguity_mm, gap, strict=True))
    return replace(fit, ambiguity_mm=(amb[0], amb[1], amb[2])), (
        f"the part's sides barely differ from the support (a face mirroring it, or of its colour): "
        f"where the support's pattern is hidden below its top, the part may stand {reading.height_mm:.1f} "
        f"mm tall, not {fit.height_mm:.1f}; the sigma takes it in")

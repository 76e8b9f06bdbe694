"""What a photo changes of the support when no part is there: the camera's tone, shadows, and the
support's pattern kept or broken. Pure functions over (H, W, 3) float32 images of the photo and
of the plate registered onto it.

Auto exposure and white balance under a camera's tone curve change the support's levels by
more than one gain (`tone_curve`); a shadow scales the support but keeps its pattern, so the
pattern tells a shadow from a part darker than it (`deepest_shadow`) and from a face that
mirrors the support, which the per-pixel shadow scale explains pixel by pixel
(`pattern_broken`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np

__all__ = ["PatternMatch", "deepest_shadow", "pattern_broken", "pattern_match", "tone_curve", "toned"]

_TONE_BIN = 16  # levels of the plate per bin of the tone curve
_TONE_MIN = 30  # pixels a bin needs to place its point


def tone_curve(P: np.ndarray, bg: np.ndarray, gain: np.ndarray, exclude: np.ndarray | None = None
               ) -> np.ndarray:
    """The camera's change of tone since the plate: per channel a power law y = a x^g (levels
    /255) from the plate's levels to the photo's, (3, 256) float32 for each level of the plate.
    Auto exposure and white balance under a camera's tone curve are no single gain: a photo
    exposed shorter by a camera with a shoulder keeps its highlights nearer their levels than its
    shadows. Fitted to the medians of the photo's levels over the support's pixels of each
    level of the plate (the part a minority of them; `exclude` (H, W) bool left out), weighed by
    their counts, the levels far off the law left out once. Under _TONE_MIN pixels in two
    levels: `gain` (3,) alone."""
    keep = np.ones(P.shape[:2], bool) if exclude is None else ~exclude
    levels = np.arange(256, dtype=np.float64)
    lut = np.empty((3, 256), np.float32)
    n_bins = 256 // _TONE_BIN
    for c in range(3):
        x, y = bg[..., c][keep], P[..., c][keep]
        ok = (x > 8) & (x < 247) & (y > 2) & (y < 253)  # clipped or black: no evidence of the law
        x, y = x[ok], y[ok]
        idx = np.minimum((x // _TONE_BIN).astype(np.intp), n_bins - 1)
        order = np.argsort(idx, kind="stable")
        bounds = np.searchsorted(idx[order], np.arange(n_bins + 1))
        xs, ys, ws = [], [], []
        for i in range(n_bins):
            sel = order[bounds[i] : bounds[i + 1]]
            if len(sel) >= max(_TONE_MIN, 0.01 * len(x)):
                xs.append(float(np.median(x[sel])))
                ys.append(float(np.median(y[sel])))
                ws.append(float(len(sel)))
        if len(xs) < 2 or max(xs) < 1.5 * min(xs):
            lut[c] = np.minimum(levels * gain[c], 255.0)
            continue
        lx, ly, w = np.log(np.asarray(xs) / 255), np.log(np.asarray(ys) / 255), np.asarray(ws)
        fit = np.polyfit(lx, ly, 1, w=np.sqrt(w))
        r = ly - np.polyval(fit, lx)
        near = np.abs(r) <= max(3 * 1.4826 * float(np.median(np.abs(r))), 0.02)
        if near.sum() >= 2 and not near.all():
            fit = np.polyfit(lx[near], ly[near], 1, w=np.sqrt(w[near]))
        g = float(np.clip(fit[0], 0.5, 2.0))
        a = float(np.exp(fit[1]))
        lut[c] = np.minimum(255.0 * a * (levels / 255) ** g, 255.0)
    return lut


def toned(bg: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """`bg` (H, W, 3) uint8 through the tone curve `lut` (3, 256): (H, W, 3) float32."""
    out = np.empty(bg.shape, np.float32)
    for c in range(3):
        np.take(lut[c], bg[..., c], out=out[..., c])
    return out


_NCC_BROKEN = 0.3  # a window whose photo correlates less than this with the support's pattern differs
_NCC_STRUCTURE = 12.0  # RGB levels: the support's pattern must vary this much in a window to judge it
_SHADOW_NCC = 0.8  # a darkened window this well correlated with the support's pattern is a shadow
_SHADOWED = 0.9  # darker than this against the support: shadowed
_SHADOW_PIXELS = 20  # coarse px of shadow needed to read its depth
_SHADOW_MARGIN = 0.15
_FLOOR_MAX = 0.35  # the least scale read is held to this at most: an umbra may fall where no pattern shows it


@dataclass(frozen=True)
class PatternMatch:
    """The photo against the support's pattern, window by window ((H, W) float32 each): ncc, their
    normalised cross-correlation; structured, where the support's pattern varies enough to judge
    it (bool); ratio, the photo's mean level over the support's."""

    ncc: np.ndarray
    structured: np.ndarray
    ratio: np.ndarray


def pattern_match(P: np.ndarray, bg: np.ndarray, window: int) -> PatternMatch:
    """The photo `P` against the support `bg` (both (H, W, 3) float32) over `window` px windows."""
    p, b = P.mean(axis=2), bg.mean(axis=2)
    k = (window, window)
    mp, mb = cv2.blur(p, k), cv2.blur(b, k)
    vp = cv2.blur(p * p, k) - mp * mp
    vb = cv2.blur(b * b, k) - mb * mb
    ncc = (cv2.blur(p * b, k) - mp * mb) / np.sqrt(np.maximum(vp, 1.0) * np.maximum(vb, 1.0))
    return PatternMatch(ncc, vb > _NCC_STRUCTURE**2, mp / np.maximum(mb, 1.0))


def deepest_shadow(match: PatternMatch, least: float) -> float:
    """The least scale a shadow puts on the support in this photo: where the support has a
    pattern and the photo shows it darkened (correlated with it, no part there), the 2nd
    percentile of the darkening, a little deeper, at least `least`; `least` where no such
    shadow is seen. A part darker than a shadow may be is then no shadow (a black part on white
    paper reads as a deep shadow's scale of it)."""
    ratio = match.ratio
    dark = match.structured & (match.ncc > _SHADOW_NCC) & (ratio < _SHADOWED) & (ratio > 0.05)
    if int(dark.sum()) < _SHADOW_PIXELS:
        return least
    return float(np.clip(np.percentile(ratio[dark], 2) - _SHADOW_MARGIN, least, _FLOOR_MAX))


def pattern_broken(match: PatternMatch, shrink: int = 0) -> np.ndarray:
    """Where the photo does not show the support's pattern: (H, W) bool. A shadow, however soft,
    and the light's change scale the pattern and a colour bled onto the support adds to it;
    neither changes its correlation with the plate. A part hides it, and a mirror-like part shows
    another piece of it, which the per-pixel shadow scale can explain pixel by pixel (a white
    square reflected as black reads as a deep shadow): the normalised cross-correlation tells
    them apart, where the support has a pattern at all. A window reaching partly over the part is
    broken too: the evidence is eroded by `shrink` px so that it does not grow the part past its
    edge."""
    broken: np.ndarray = (match.structured & (match.ncc < _NCC_BROKEN)).astype(np.uint8)
    if shrink > 0:
        broken = cv2.erode(broken, np.ones((2 * shrink + 1, 2 * shrink + 1), np.uint8))
    return cast("np.ndarray", broken > 0)

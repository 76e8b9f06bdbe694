"""Sub-pixel location of a face's edges from the colour edges near the clicked corners.

Clicks are a few pixels off; dimensions must not be. Each side of a clicked quad is searched
in a band around it: the image is sampled on profiles normal to the side, a derivative-of-
Gaussian gives the colour-edge strength along each profile, and every local maximum is a
candidate at sub-pixel precision (parabola through the peak). A straight line is then chosen
by consensus (the line that most profiles support, not the strongest one: a printed label
near the edge is a strong but shorter line) and refined by weighted least squares.
The corners are the intersections of adjacent lines.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["EdgeFit", "fit_edge", "intersect", "inward", "line_through", "refine_quad", "side_bounds"]

_STEP = 0.5  # profile sample spacing, px
_MAX_PROFILES = 200
_CANDIDATES = 4  # local maxima kept per profile
_MAX_TILT = np.tan(np.radians(12.0))  # the true edge is within this angle of the clicked one


def _gaussian(sigma: float, order: int) -> np.ndarray:
    x = np.arange(-int(4 * sigma + 0.5), int(4 * sigma + 0.5) + 1, dtype=np.float64)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    g /= g.sum()
    return (g if order == 0 else -x / sigma**2 * g).astype(np.float32)


_SMOOTH = _gaussian(1.0, 0)  # along the side, in profiles
_DERIVATIVE = _gaussian(1.0 / _STEP, 1)  # across the side: sigma 1 px
_YCC = np.array([[0.299, 0.587, 0.114],  # RGB -> (Y, Cb, Cr) as JPEG has them (BT.601)
                 [-0.168736, -0.331264, 0.5],
                 [0.5, -0.418688, -0.081312]])
# Luminance-led first (precise under JPEG); full colour as the second try for edges between
# colours of nearly equal brightness, which the first one cannot see.
_COLOUR_PASSES = tuple((_YCC * np.array([[1.0], [w], [w]])).astype(np.float32) for w in (0.25, 1.0))
_HYPOTHESES = 120
_SCORING_PROFILES = 60


@dataclass(frozen=True)
class EdgeFit:
    """A fitted edge: the line a*x + b*y + c = 0 with (a, b) a unit normal."""

    line: np.ndarray  # (3,) float64
    support: float  # fraction of profiles that agree with the line, 0-1
    rms_px: float  # RMS distance of the agreeing edge points to the line
    fitted: bool  # False when no edge was found and the clicked side was kept
    points: np.ndarray | None = None
    """(N, 2) float64 image (x, y) px of the edge as sampled along the side (one per profile that
    sees it), following its curvature: a lens's distortion bends straight edges, and these
    samples are what a plumb-line estimate of it reads. None when the edge was not fitted."""


def line_through(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The normalised line (a, b, c) through two image points: (p, 1) x (q, 1), written out
    (np.cross's generality cost more than the rest of a side's bounds)."""
    px, py, qx, qy = float(p[0]), float(p[1]), float(q[0]), float(q[1])
    line = np.array([py - qy, qx - px, px * qy - py * qx])
    normalised: np.ndarray = line / np.hypot(line[0], line[1])
    return normalised


def intersect(l1: np.ndarray, l2: np.ndarray) -> np.ndarray:
    """Intersection (x, y) of two lines in (a, b, c) form."""
    a1, b1, c1 = (float(v) for v in l1)
    a2, b2, c2 = (float(v) for v in l2)
    h = np.array([b1 * c2 - c1 * b2, c1 * a2 - a1 * c2, a1 * b2 - b1 * a2])
    point: np.ndarray = h[:2] / h[2]
    return point


def _profiles(
    image: np.ndarray, p: np.ndarray, q: np.ndarray, search_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    length = float(np.linalg.norm(q - p))
    d = (q - p) / length
    n = np.array([-d[1], d[0]])
    # Stay clear of the corners: a click a few px off must not put profiles past the face's end.
    inset = min(max(0.1 * length, 8.0), 0.3 * length)
    count = int(min(_MAX_PROFILES, max(8, length - 2 * inset)))
    s = np.linspace(inset, length - inset, count)
    margin = 3.0  # room for the derivative filter at the band's ends
    t = np.arange(-search_px - margin, search_px + margin + 1e-9, _STEP)
    xy = p + s[:, None, None] * d + t[None, :, None] * n
    return s, t, d, n, _bilinear(image, xy[..., 0], xy[..., 1]), int(margin / _STEP)


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of an (H, W, C) image at float positions, as float32 (..., C).

    Only the small box the samples fall in is converted to float (OpenCV's remap would round
    its output back to 8 bits on a uint8 image, losing the sub-pixel information).
    """
    h, w = image.shape[:2]
    x0 = int(np.clip(np.floor(x.min()) - 1, 0, w - 1))
    y0 = int(np.clip(np.floor(y.min()) - 1, 0, h - 1))
    x1 = int(np.clip(np.ceil(x.max()) + 2, x0 + 1, w))
    y1 = int(np.clip(np.ceil(y.max()) + 2, y0 + 1, h))
    crop = np.ascontiguousarray(image[y0:y1, x0:x1], dtype=np.float32)
    out = cv2.remap(crop, (x - x0).astype(np.float32), (y - y0).astype(np.float32),
                    interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out if out.ndim == 3 else out[..., None]


def _candidates(
    samples: np.ndarray, t: np.ndarray, margin: int, colour: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel edge positions (profiles, K) along t, with their strengths; NaN when absent."""
    # JPEG keeps chroma at half resolution, which blurs and shifts colour edges by up to half a
    # pixel; luminance is kept at full resolution. So luminance locates the edge, and chroma,
    # down-weighted, still finds edges between colours of equal brightness.
    samples = samples @ colour.T
    # Smooth along the side (noise) and differentiate across it (the edge), in one pass.
    grad = cv2.sepFilter2D(np.ascontiguousarray(samples, dtype=np.float32), -1, _DERIVATIVE,
                           _SMOOTH, borderType=cv2.BORDER_REPLICATE)
    strength = np.sqrt(grad[..., 0] ** 2 + grad[..., 1] ** 2 + grad[..., 2] ** 2)
    inner = strength[:, margin - 1 : strength.shape[1] - margin + 1]
    left, mid, right = inner[:, :-2], inner[:, 1:-1], inner[:, 2:]
    is_peak = (mid > left) & (mid >= right)
    floor = max(0.5, 0.15 * float(np.percentile(mid.max(axis=1), 75)))
    is_peak &= mid >= np.maximum(floor, 0.15 * mid.max(axis=1, keepdims=True))
    score = np.where(is_peak, mid, -np.inf)
    order = np.argpartition(-score, _CANDIDATES - 1, axis=1)[:, :_CANDIDATES]
    rows = np.arange(score.shape[0])[:, None]
    valid = np.isfinite(score[rows, order])
    denom = left[rows, order] - 2 * mid[rows, order] + right[rows, order]
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(denom < 0, 0.5 * (left[rows, order] - right[rows, order]) / denom, 0.0)
    pos = t[margin + order] + np.clip(delta, -0.5, 0.5) * _STEP
    return np.where(valid, pos, np.nan), np.where(valid, mid[rows, order], 0.0)


def _consensus(
    s: np.ndarray, pos: np.ndarray, weight: np.ndarray, tol: float
) -> tuple[float, float] | None:
    """Offset and slope (a, b) of the line t = a + b*s that most profiles support."""
    rng = np.random.default_rng(0)  # deterministic: the same image always gives the same line
    rows, cols = np.nonzero(np.isfinite(pos))
    if rows.size < 2:
        return None
    i = rng.integers(0, rows.size, _HYPOTHESES)
    j = rng.integers(0, rows.size, _HYPOTHESES)
    keep = rows[i] != rows[j]
    i, j = i[keep], j[keep]
    ti, tj = pos[rows[i], cols[i]], pos[rows[j], cols[j]]
    si, sj = s[rows[i]], s[rows[j]]
    b = (tj - ti) / (sj - si)
    keep = np.abs(b) <= _MAX_TILT
    if not keep.any():
        return None
    a, b = (ti - b * si)[keep], b[keep]
    # Scoring on a subset of the profiles is enough to rank the hypotheses.
    sub = slice(None, None, max(1, len(s) // _SCORING_PROFILES))
    filled = np.where(np.isfinite(pos[sub]), pos[sub], np.inf).astype(np.float32)
    line = (a[:, None] + b[:, None] * s[None, sub]).astype(np.float32)
    # Per candidate column (a handful): reductions over that short last axis were most of the time.
    seen = np.zeros(line.shape, dtype=bool)
    strongest = np.zeros(line.shape, dtype=weight.dtype)
    for k, w in zip(filled.T, weight[sub].T, strict=True):
        near = np.abs(k[None] - line) <= tol
        seen |= near
        np.maximum(strongest, np.where(near, w[None], 0), out=strongest)
    support = seen.sum(axis=1)
    strength = strongest.sum(axis=1)
    # Prefer the line most profiles see; among equals, the stronger and the nearer to the click.
    best = np.lexsort((np.abs(a), -strength, -support))[0]
    return float(a[best]), float(b[best])


def _refine(
    s: np.ndarray, pos: np.ndarray, weight: np.ndarray, a: float, b: float
) -> tuple[float, float, float, float] | None:
    filled = np.where(np.isfinite(pos), pos, np.inf)
    resid = np.empty(0)  # set by the first pass
    for tol in (1.0, 0.6, 0.6):
        resid = np.abs(filled - (a + b * s)[:, None])
        k = np.argmin(resid, axis=1)
        r = resid[np.arange(len(s)), k]
        use = r <= tol
        if use.sum() < 3:
            return None
        w = weight[np.arange(len(s)), k][use]
        A = np.stack([np.ones(use.sum()), s[use]], axis=1) * np.sqrt(w)[:, None]
        y = pos[np.arange(len(s)), k][use] * np.sqrt(w)
        a, b = np.linalg.lstsq(A, y, rcond=None)[0]
        resid = (pos[np.arange(len(s)), k] - (a + b * s))[use]
    return float(a), float(b), float(use.mean()), float(np.sqrt(np.mean(resid**2)))


Bound = tuple[np.ndarray, float]
"""A half-plane (line, minimum): candidates must satisfy a*x + b*y + c >= minimum."""


def fit_edge(image: np.ndarray, p: np.ndarray, q: np.ndarray, *, search_px: float = 10.0,
             bounds: tuple[Bound, ...] = ()) -> EdgeFit:
    """Locate the colour edge near the clicked side p -> q to sub-pixel precision.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        RGB image, 0-255 units (uint8, or float for 16-bit inputs).
    p, q : ndarray, shape (2,)
        Clicked ends of the side, image (x, y) in pixels.
    search_px : float
        How far (px) on either side of the clicked side the edge may lie.
    bounds : tuple of (line, minimum)
        Half-planes the edge must lie in (e.g. not beyond the neighbouring sides, nor past the
        middle of the face), so that a stronger nearby edge cannot be taken for this one.

    Returns
    -------
    EdgeFit
        The fitted line; `fitted` is False (and the clicked line is kept) when fewer than
        40 % of the profiles agree on any line.
    """
    s, t, d, n, samples, margin = _profiles(image, p, q, search_px)
    refined = None
    for colour in _COLOUR_PASSES:
        pos, weight = _candidates(samples, t, margin, colour)
        if bounds:
            xy = p + s[:, None, None] * d + np.nan_to_num(pos)[..., None] * n
            for line, minimum in bounds:
                outside = xy @ line[:2] + line[2] < minimum
                pos[outside] = np.nan
                weight[outside] = 0.0
        found = _consensus(s, pos, weight, tol=0.75)
        refined = _refine(s, pos, weight, *found) if found else None
        if refined is not None and refined[2] >= 0.4:
            break
    if refined is None or refined[2] < 0.4:
        return EdgeFit(line_through(p, q), 0.0 if refined is None else refined[2], 0.0, False)
    a, b, support, rms = refined
    start = p + a * n
    end = p + (q - p) + (a + b * float(np.linalg.norm(q - p))) * n
    return EdgeFit(line_through(start, end), support, rms, True, _curve_points(s, pos, p, d, n, a, b))


_CURVE_REACH_PX = 3.0  # how far a bent edge may stray from its chord (a phone lens: a few px)
_CURVE_TOL_PX = 0.75


def _curve_points(s: np.ndarray, pos: np.ndarray, p: np.ndarray, d: np.ndarray, n: np.ndarray,
                  a: float, b: float) -> np.ndarray | None:
    """The edge's samples (N, 2) image (x, y) px, following its curvature.

    The straight fit keeps only the samples within 0.6 px of its line, which on an edge bent by
    the lens are the middle ones. Here each profile's candidate nearest the line (within
    _CURVE_REACH_PX) seeds a quadratic t = a + b s + c s^2 (the lowest order that bends), and the
    candidates within _CURVE_TOL_PX of that quadratic are kept.
    """
    filled = np.where(np.isfinite(pos), pos, np.inf)
    rows = np.arange(len(s))
    guess: np.ndarray = a + b * s
    for tol in (_CURVE_REACH_PX, _CURVE_TOL_PX, _CURVE_TOL_PX):
        k = np.argmin(np.abs(filled - guess[:, None]), axis=1)
        t = filled[rows, k]
        use = np.abs(t - guess) <= tol
        if use.sum() < 6:
            return None
        # Centred and scaled abscissa: a well-conditioned quadratic.
        mid, half = float(s.mean()), float(np.ptp(s)) / 2 or 1.0
        u = (s - mid) / half
        coef = np.polyfit(u[use], t[use], 2)
        guess = np.polyval(coef, u)
    points: np.ndarray = p + s[use, None] * d + t[use, None] * n
    return points


def inward(line: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """The line oriented so that `inside` gives a positive value."""
    return line if line[:2] @ inside + line[2] >= 0 else -line


def side_bounds(quad: np.ndarray, side: int, *, margin_px: float = 3.0) -> tuple[Bound, ...]:
    """Where side `side` of a clicked quad may lie: within `margin_px` of the neighbouring sides'
    clicked lines, and nearer to its own click than to the opposite side."""
    centre = quad.mean(axis=0)
    lines = [inward(line_through(quad[i], quad[(i + 1) % 4]), centre) for i in range(4)]
    own_mid = (quad[side] + quad[(side + 1) % 4]) / 2
    opposite = lines[(side + 2) % 4]
    half_width = 0.5 * float(opposite[:2] @ own_mid + opposite[2])
    return ((lines[(side - 1) % 4], -margin_px), (lines[(side + 1) % 4], -margin_px),
            (opposite, half_width))


def refine_quad(
    image: np.ndarray,
    quad: np.ndarray,
    *,
    search_px: float = 10.0,
    known: dict[int, EdgeFit] | None = None,
    extra_bounds: dict[int, tuple[Bound, ...]] | None = None,
) -> tuple[np.ndarray, list[EdgeFit]]:
    """Fit all four sides of a clicked quad and return the refined corners.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
    quad : ndarray, shape (4, 2)
        Clicked corners, TL, TR, BR, BL, image (x, y) px.
    known : dict, optional
        Sides already fitted (index 0 top, 1 right, 2 bottom, 3 left), e.g. the edge a side
        face shares with the front face.
    extra_bounds : dict, optional
        Further half-planes per side (see :func:`fit_edge`).

    Returns
    -------
    corners : ndarray, shape (4, 2), float64
    fits : list of EdgeFit
    """
    known = known or {}
    extra_bounds = extra_bounds or {}
    fits = [
        known[i] if i in known else fit_edge(
            image, quad[i], quad[(i + 1) % 4], search_px=search_px,
            bounds=side_bounds(quad, i) + extra_bounds.get(i, ()))
        for i in range(4)
    ]
    with np.errstate(divide="ignore", invalid="ignore"):
        corners = np.stack([intersect(fits[(i - 1) % 4].line, fits[i].line) for i in range(4)])
    return corners, fits

"""The part against the empty support (the photo re-registered on it: `registration`): the light's
change taken out, shadows told from the part, and the part's outline.

Everything here works in the undistorted (pinhole) image of the station's camera.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import cv2
import numpy as np

from prismcore.errors import PartRefusedError
from prismcore.station.photometry import deepest_shadow, pattern_broken, pattern_match, tone_curve, toned

__all__ = ["SHADOW_RANGE", "Silhouette", "difference2", "norm2", "planes", "segment_part", "shadow_ratio"]

SHADOW_RANGE = (0.25, 1.08)  # a shadow (or the light's change) scales the background by this
_MIN_AREA_FRACTION = 2e-4  # of the photo: smaller blobs are noise or dust
_SECOND_PART = 0.2  # a second blob this large against the first is a second part
_NO_PART = ("no part found on the support (nothing differs from the plate): put the part in view on the "
            "support; a part of the support's colour (dark on the black squares) needs a mat of another "
            "colour under it")
_LOW_CONTRAST = 25.0  # RGB levels: a part whose colour differs less from the support is flagged


@dataclass(frozen=True)
class Silhouette:
    """The part's outline in the undistorted photo.

    contour : (N, 2) float64 image (x, y) px, the outline's pixels in order. mask : (H, W) bool.
    contrast : median RGB distance of the part's pixels from the support (levels).
    origin : (x, y) px of the part's window in the photo: `difference` and `window_mask` cover it.
    """

    contour: np.ndarray
    mask: np.ndarray
    contrast: float
    area_px: int
    warnings: list[str]
    # (h, w) float32, the window: the photo's distance from the shadow-scaled support (442 deep
    # inside the part, where it is not computed)
    difference: np.ndarray
    origin: tuple[int, int] = (0, 0)
    # blobs much smaller than the part, not joined to it: the bounding box (x, y, width, height)
    # px of each, the photo's pixels
    others: list[tuple[float, ...]] = field(default_factory=list)
    # how the plate was compared: (3, 256) the camera's tone change since it, and the deepest
    # shadow's scale; and whether part of the outline was found only where the pattern broke
    tone: np.ndarray | None = None
    shadow_least: float = SHADOW_RANGE[0]
    mirrored: bool = False

    @property
    def window(self) -> tuple[slice, slice]:
        """The part's window as (rows, columns) slices of the photo."""
        x0, y0 = self.origin
        h, w = self.difference.shape
        return slice(y0, y0 + h), slice(x0, x0 + w)


def planes(image: np.ndarray) -> list[np.ndarray]:
    """`image` (H, W, C) as its C channel planes (views, (H, W) each)."""
    return [image[..., c] for c in range(image.shape[2])]


def norm2(planes: list[np.ndarray]) -> np.ndarray:
    """The squared norm (H, W) over channel `planes` (a new array; the planes are left as they are)."""
    out: np.ndarray = planes[0] * planes[0]
    for q in planes[1:]:
        out += q * q
    return out


def shadow_ratio(p: list[np.ndarray], b: list[np.ndarray], b2: np.ndarray | None = None) -> np.ndarray:
    """The scale of support planes `b` nearest photo planes `p` per pixel, unclipped: their dot
    product over `b2` (the support's squared norm, `norm2(b)` if not given) + 1, (H, W)."""
    dot = p[0] * b[0]
    for pc, bc in zip(p[1:], b[1:], strict=True):
        dot += pc * bc
    return cast("np.ndarray", dot / ((norm2(b) if b2 is None else b2) + 1.0))


def difference2(p: list[np.ndarray], b: list[np.ndarray], b2: np.ndarray,
                shadow: tuple[np.ndarray | float, np.ndarray | float] = SHADOW_RANGE,
                clipped: list[np.ndarray] | None = None) -> np.ndarray:
    """The squared distance of photo planes `p` from support planes `b` (`b2` their squared norm)
    scaled by the best shadow factor within `shadow` (the least and the most: numbers, or (H, W)
    arrays, per pixel), per pixel, float32: a channel-plane loop (numpy reduces a last axis of 3
    slowly). clipped : per channel, (H, W) bool where the plate was clipped at white: there the
    support was at least as bright as the plate shows, so only a photo darker than the model
    differs. (The shadow's scale is still read on every channel: read on the unclipped ones
    alone, a pixel clipped in two channels gave a noisy one, and blobs of 17 and 28 "parts".)"""
    ratio = shadow_ratio(p, b, b2)
    s = np.clip(ratio, *shadow, out=ratio).astype(np.float32, copy=False)
    out: np.ndarray | None = None
    for i, (pc, bc) in enumerate(zip(p, b, strict=True)):
        # A brighter light saturates a channel at 255 where the plate's did not: the model clips too.
        e = pc - np.minimum(s * bc, 255.0)
        if clipped is not None:
            np.minimum(e, 0.0, out=e, where=clipped[i])
        e *= e
        out = e if out is None else np.add(out, e, out=out)
    assert out is not None
    return out


_AT_WHITE = 254  # a plate's channel at this level or above was clipped: its support as bright or brighter
_LIGHT_MIN_PIXELS = 100  # unclipped support pixels needed to measure the light's change


def _gain(P: np.ndarray, bg: np.ndarray) -> tuple[np.ndarray, str | None]:
    """The light's change: one gain per channel, the median ratio (the part is a minority), and a
    warning when too few of the support's pixels are unclipped to measure it (gain 1 then)."""
    b, p = planes(bg), planes(P)
    ok = (np.minimum(np.minimum(b[0], b[1]), b[2]) > 30) & (np.maximum(np.maximum(b[0], b[1]), b[2]) < 245)
    ok &= np.maximum(np.maximum(p[0], p[1]), p[2]) < 245  # no clipped channel
    count = int(ok.sum())
    if count <= _LIGHT_MIN_PIXELS:
        return np.ones(3, np.float32), (
            f"the light's change since the plate could not be measured ({count} of the support's pixels "
            f"unclipped, at most {_LIGHT_MIN_PIXELS}): taken as none; the part's outline may be off")
    return np.array([np.median(pc[ok] / bc[ok]) for pc, bc in zip(p, b, strict=True)], np.float32), None


_CORE = 5  # coarse px: the part's coarse blob shrunk by this lies inside its outline for sure
_STRIP = 48  # rows of the window whose residual is computed together
_MIN_RUN = 64  # columns: a shorter run inside the part is computed (each block costs some fixed work)
_INSIDE = np.float32(442.0)  # the residual read inside the part where it is not computed (> any RGB distance)


def _residual(P: np.ndarray, bg: np.ndarray, core: np.ndarray | None = None,
              shadow: tuple[float, float] = SHADOW_RANGE, clipped: np.ndarray | None = None) -> np.ndarray:
    """A shadow scales the support; the part does not. The support is also compared shifted by a
    pixel each way and the least difference kept: the registration's last fraction of a pixel
    then shows no difference along the board's edges, while the part differs from every shift.
    (The shifts wrap round the window, as np.roll.)

    core : (H, W) bool, optional: pixels deep inside the part. In each strip of _STRIP rows, the
        run of columns inside it on every row of the strip is not computed and reads _INSIDE: the
        outline cannot lie there, and a large part's inside was most of the segmentation's time.
        Every pixel computed has the value it has without `core`.
    clipped : (H, W, 3) bool, optional: where the plate (as `bg`) was clipped at white, per
        channel (`difference2`); None or none set: none.
    """
    h, w = P.shape[:2]
    p = planes(P)
    padded = [np.ascontiguousarray(q) for q in planes(np.pad(bg, ((1, 1), (1, 1), (0, 0)), mode="wrap"))]
    padded2 = norm2(padded)
    at_white = None
    if clipped is not None and clipped.any():
        wrapped = np.pad(clipped, ((1, 1), (1, 1), (0, 0)), mode="wrap")
        at_white = [np.ascontiguousarray(q) for q in planes(wrapped)]
    runs = _runs(core, h, w)
    out = None if runs == [(0, h, 0, w)] else np.full((h, w), _INSIDE, np.float32)
    for r0, r1, c0, c1 in runs:
        pr = [np.ascontiguousarray(q[r0:r1, c0:c1]) for q in p]
        best: np.ndarray | None = None
        for dx, dy in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            rows, cols = slice(r0 + 1 - dy, r1 + 1 - dy), slice(c0 + 1 - dx, c1 + 1 - dx)
            d2 = difference2(pr, [q[rows, cols] for q in padded], padded2[rows, cols], shadow,
                             None if at_white is None else [q[rows, cols] for q in at_white])
            best = d2 if best is None else np.minimum(best, d2, out=best)
        assert best is not None
        if out is None:
            return cast("np.ndarray", np.sqrt(best, out=best))
        out[r0:r1, c0:c1] = np.sqrt(best, out=best)
    assert out is not None
    return out


def _runs(core: np.ndarray | None, h: int, w: int) -> list[tuple[int, int, int, int]]:
    """The blocks (row from, row to, column from, column to) of an (h, w) window :func:`_residual`
    computes: all of it without `core`; else, strip by strip, the columns either side of the run
    inside `core` on every row of the strip (one run: the part is convex), rows with no such run
    together (each block costs some fixed work)."""
    if core is None:
        return [(0, h, 0, w)]
    blocks: list[tuple[int, int, int, int]] = []
    for r0 in range(0, h, _STRIP):
        r1 = min(h, r0 + _STRIP)
        inside: np.ndarray = np.all(core[r0:r1], axis=0)
        a, b = int(np.argmax(inside)), w - int(np.argmax(inside[::-1]))
        if inside.any() and b - a >= _MIN_RUN and inside[a:b].all():
            blocks += [(r0, r1, c0, c1) for c0, c1 in ((0, a), (b, w)) if c1 > c0]
        elif blocks and blocks[-1][1] == r0 and blocks[-1][2:] == (0, w):
            blocks[-1] = (blocks[-1][0], r1, 0, w)
        else:
            blocks.append((r0, r1, 0, w))
    return blocks


def _mask(resid: np.ndarray, noise: float, scale: float) -> np.ndarray:
    """Hysteresis: a face barely apart from a dark square is kept where it joins the part. (A weak
    threshold raised with the support's texture was tried: it broke a dark face on the board's
    dark squares, where the texture is the board's hidden pattern.)"""
    k = max(3, round(5 * scale) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    strong: np.ndarray = cv2.morphologyEx(
        (resid > max(14.0, 4.0 * noise)).astype(np.uint8), cv2.MORPH_OPEN, kernel
    )
    low = max(6.0, 2.5 * noise)
    weak: np.ndarray = cv2.morphologyEx((resid > low).astype(np.uint8), cv2.MORPH_OPEN, kernel)
    n_weak, weak_labels = cv2.connectedComponents(weak | strong, connectivity=8)
    keep = np.zeros(n_weak, np.uint8)
    keep[np.unique(weak_labels[strong > 0])] = 1
    keep[0] = 0
    close = max(3, round(9 * scale) | 1)
    return cv2.morphologyEx(
        keep[weak_labels], cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (close, close))
    )


_NCC_WINDOW = 5  # coarse px: the window the support's pattern is compared over
_NCC_FULL = 7  # at full size
_NCC_SHRINK = 2
_BROKEN_LEVEL = np.float32(60.0)  # the residual a window with its pattern broken is given, at least
_MIRRORED = 0.03  # of the part's area: broken pattern beyond this joins the outline
_TONE_BETTER = 0.8  # the tone curve is taken where the support's median residual is this much of the gain's


_SPLIT_GAP_PX = 3.0  # coarse px
_SPLIT_GAP = 0.3  # of the part's size (the square root of its area)
_COARSE = 4  # the part is first found in a photo this many times smaller
_THIN = 0.5  # a blob apart from the part narrower than this share of the part (mean widths)...
_LONG = 6.0  # ...and this many times longer than thick is a line, not a part


def _blobs(labels: np.ndarray, ids: list[int], size: tuple[int, int]) -> np.ndarray:
    """The coarse `labels`' blobs `ids` at the photo's `size` (w, h): (H, W) bool."""
    return cast("np.ndarray", cv2.resize(np.isin(labels, ids).astype(np.uint8), size,
                                         interpolation=cv2.INTER_NEAREST) > 0)


def _width_and_length(labels: np.ndarray, stats: np.ndarray, i: int) -> tuple[float, float]:
    """Blob `i`'s mean width and length (px of `labels`): for a strip, its area over half its
    outline's length, and half that length; a disc's "length" is then under twice its width."""
    x, y, bw, bh = (int(v) for v in stats[i, :4])
    inside = np.pad(labels[y:y + bh, x:x + bw] == i, 1).astype(np.uint8)
    contours, _ = cv2.findContours(inside, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    half = max(sum(cv2.arcLength(c, True) for c in contours) / 2, 1.0)
    return float(stats[i, cv2.CC_STAT_AREA]) / half, half


def _thin(labels: np.ndarray, stats: np.ndarray, blobs: list[int]) -> list[int]:
    """The `blobs` that are thin and long and apart from the widest of them (a cable, a ruler's
    edge, a printed line, a sheet's edge: no box, whose silhouette is convex and as wide as its
    smaller side): under _THIN of its mean width, over _LONG times as long as they are wide, and
    farther from it than a piece of the part split off would lie (`_SPLIT_GAP`)."""
    if len(blobs) < 2:
        return []
    shapes = {i: _width_and_length(labels, stats, i) for i in blobs}
    widest = max(shapes, key=lambda i: shapes[i][0])
    narrow = [i for i, (width, length) in shapes.items()
              if width < _THIN * shapes[widest][0] and length > _LONG * width]
    return _apart_from(labels, stats, widest, narrow) if narrow else []


def _apart_from(labels: np.ndarray, stats: np.ndarray, part: int, blobs: list[int]) -> list[int]:
    """The `blobs` farther from blob `part` than a piece of it split off would lie: a band of its
    colour meeting the support's splits a part by a small gap (_SPLIT_GAP_PX, _SPLIT_GAP of its
    size, the square root of its area)."""
    gap = cv2.distanceTransform((labels != part).astype(np.uint8), cv2.DIST_L2, 3)
    reach = max(_SPLIT_GAP_PX, _SPLIT_GAP * float(np.sqrt(stats[part, cv2.CC_STAT_AREA])))
    return [i for i in blobs if float(gap[labels == i].min()) > reach]


def _unseen(plate_shape: tuple[int, ...], homography: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: where the plate, warped by `homography` into an image of `size` (W, H), does not
    reach, and a pixel around. There the warp's replicated border invents a support (the camera
    moved since the plate was taken and the photo shows more of the scene): nothing read there is
    evidence of a part."""
    reach = cv2.warpPerspective(np.full(plate_shape, 255, np.uint8), homography, size,
                                flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return cv2.dilate((reach < 255).view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)


def segment_part(
    photo_u: np.ndarray, plate_u: np.ndarray, homography: np.ndarray, *, skip_inside: bool = True,
    rests_on: np.ndarray | None = None,
) -> Silhouette:
    """The one part in `photo_u` against the plate (warped by `homography` onto the photo).

    Found first at a quarter of the size (how many parts, where), then outlined at full size in
    the part's own window. skip_inside : the full-size residual is not computed deep inside the
    coarse blob (False: over the whole window; the tests compare the outlines). rests_on : (H, W)
    bool: where the part may rest (a hand-held board); blobs away from it are left out, and said.

    Raises
    ------
    InputError
        No part, more than one, or a part cut by the photo's edge.
    """
    h, w = photo_u.shape[:2]
    small = (w // _COARSE, h // _COARSE)
    # The plate warped onto the photo at a quarter of the size (the plate reduced, the homography
    # scaled: pixel centres x_s = (x + 0.5) / f - 0.5), and at full size in the part's window only.
    to_small = np.array([[small[0] / w, 0, 0.5 * small[0] / w - 0.5],
                         [0, small[1] / h, 0.5 * small[1] / h - 0.5], [0, 0, 1.0]])
    Ps = cv2.resize(photo_u, small, interpolation=cv2.INTER_AREA).astype(np.float32)
    plate_s = cv2.resize(plate_u, small, interpolation=cv2.INTER_AREA)
    Hs = to_small @ homography @ np.linalg.inv(to_small)
    Bs8 = cv2.warpPerspective(plate_s, Hs, small, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    unseen_s = _unseen(plate_s.shape[:2], Hs, small)
    Bs = Bs8.astype(np.float32)
    gain, light_warning = _gain(Ps, Bs)
    # The part first against the plate under the light's gain, then the camera's tone curve fitted
    # without it, and kept only where it explains the support clearly better than the gain: a
    # light that only changed needs none, and a curve fitted to a large part's levels would invent one.
    linear = np.minimum(np.arange(256, dtype=np.float32)[None] * gain[:, None], 255.0)
    white_s = Bs8 >= _AT_WHITE
    resid_g = _residual(Ps, toned(Bs8, linear), clipped=white_s)
    resid_g[unseen_s] = 0.0
    first = _mask(resid_g, float(np.median(resid_g)) * 1.4826 + 1.0, 1 / _COARSE) > 0
    support = cv2.dilate(first.astype(np.uint8), np.ones((5, 5), np.uint8)) == 0
    lut = tone_curve(Ps, Bs, gain, ~support)
    resid_t = _residual(Ps, toned(Bs8, lut), clipped=white_s)
    if not float(np.median(resid_t[support])) < _TONE_BETTER * float(np.median(resid_g[support])):
        lut = linear
    Bs = toned(Bs8, lut)
    coarse_match = pattern_match(Ps, Bs, _NCC_WINDOW)  # one pass for the shadow's depth and the pattern
    shadow = (deepest_shadow(coarse_match, SHADOW_RANGE[0]), SHADOW_RANGE[1])
    resid_s = _residual(Ps, Bs, shadow=shadow, clipped=white_s)
    broken_s = pattern_broken(coarse_match)
    resid_s[broken_s] = np.maximum(resid_s[broken_s], _BROKEN_LEVEL)
    resid_s[unseen_s] = 0.0
    noise_s = float(np.median(resid_s)) * 1.4826 + 1.0
    mask_s = _mask(resid_s, noise_s, 1 / _COARSE)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask_s, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    min_area = _MIN_AREA_FRACTION * small[0] * small[1]
    big = [i + 1 for i in np.argsort(-areas) if areas[i] >= min_area]
    on = None if rests_on is None else cv2.resize(rests_on.view("u1"), small, interpolation=cv2.INTER_AREA)
    off_support = [] if on is None else [i for i in big if not on[labels == i].any()]
    big = [i for i in big if i not in off_support]
    thin = _thin(labels, stats, big)  # left out, and said
    big = [i for i in big if i not in thin]
    if not big:
        raise PartRefusedError(_NO_PART + f" ({len(off_support)} off the board left out)" * bool(off_support),
                          photo_u, _blobs(labels, off_support, (w, h)))
    first = big[0]
    # A blob within a small gap of the part is the part split by a band of its colour meeting the
    # support's (one face alike the table behind it): joined. Farther, it is a second part; a blob
    # much smaller than the part may be a piece of it, a small part or a speck: judged by the
    # caller against the fitted box and sized on the plane (`Silhouette.others`), never dropped
    # unsaid.
    far = _apart_from(labels, stats, first, big[1:])
    others = [i for i in far if areas[i - 1] >= _SECOND_PART * areas[first - 1]]
    joined = [i for i in big[1:] if i not in far and areas[i - 1] >= _SECOND_PART * areas[first - 1]]
    if others:
        raise PartRefusedError(f"{1 + len(others)} parts found: one part per photo; take the other things "
                               "off the support", photo_u,
                          _blobs(labels, [first, *others], (w, h)))
    # the smaller blobs, near or far: the caller keeps those inside the fitted box's outline
    apart = [tuple(float(v) * _COARSE for v in stats[i, :4]) for i in big[1:] if i not in joined]
    pieces = [first, *joined]
    x0, y0 = (int(min(stats[i, k] for i in pieces)) for k in (0, 1))
    bw = int(max(stats[i, 0] + stats[i, 2] for i in pieces)) - x0
    bh = int(max(stats[i, 1] + stats[i, 3] for i in pieces)) - y0
    if x0 <= 0 or y0 <= 0 or x0 + bw >= small[0] or y0 + bh >= small[1]:
        raise PartRefusedError("the part is cut by the photo's edge: move it into view", photo_u,
                          _blobs(labels, pieces, (w, h)))
    # (the unseen band's residual is nought: a part reaching into it stops at its border)
    if (cv2.dilate(np.isin(labels, pieces).view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
            & unseen_s).any():
        raise PartRefusedError(
            "the part reaches the photo's edge where the empty support's photo shows nothing (the "
            "camera has moved since calibration): move the part away from the edge, or calibrate "
            "again", photo_u, _blobs(labels, pieces, (w, h)))
    # The part's window at full size, with a margin of support around it.
    m = 6
    X0, Y0 = max(0, (x0 - m) * _COARSE), max(0, (y0 - m) * _COARSE)
    X1, Y1 = min(w, (x0 + bw + m) * _COARSE), min(h, (y0 + bh + m) * _COARSE)
    P = photo_u[Y0:Y1, X0:X1].astype(np.float32)
    window_h = np.array([[1, 0, -X0], [0, 1, -Y0], [0, 0, 1.0]]) @ homography
    bg8 = cv2.warpPerspective(
        plate_u, window_h, (X1 - X0, Y1 - Y0), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    bg = toned(bg8, lut)
    # the coarse blob at full size in the window (nearest: each coarse pixel's full-size pixels)
    cols = np.minimum(np.arange(X0, X1) * small[0] // w, small[0] - 1)
    rows = np.minimum(np.arange(Y0, Y1) * small[1] // h, small[1] - 1)
    blob = np.isin(labels, pieces).astype(np.uint8)
    core = cv2.erode(blob, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * _CORE + 1,) * 2))
    resid = _residual(P, bg, core[np.ix_(rows, cols)] > 0 if skip_inside else None, shadow,
                      clipped=bg8 >= _AT_WHITE)
    resid[_unseen(plate_u.shape[:2], window_h, (X1 - X0, Y1 - Y0))] = 0.0
    near: np.ndarray = blob[np.ix_(rows, cols)]
    near = cv2.dilate(near, np.ones((9, 9), np.uint8))
    outside = resid[near == 0]
    noise = float(np.median(outside)) * 1.4826 + 1.0 if outside.size > 100 else noise_s
    # Where the support's pattern is broken near the part, the part is there even if no pixel
    # differs enough: a dark part reads as a deep shadow of white paper pixel by pixel, but a
    # shadow keeps the step from a black square to the white, and a part does not. The coarse
    # pass counts it; so does this one, or a part found coarse was lost here ("no part found").
    broken = pattern_broken(pattern_match(P, bg, _NCC_FULL), _NCC_SHRINK) & (near > 0)
    # (the mask without that evidence tells what it alone added: the same mask where none is near)
    plain = _mask(resid, noise, 1.0)
    mask = _mask(np.maximum(resid, _BROKEN_LEVEL, where=broken, out=resid.copy()), noise, 1.0) \
        if broken.any() else plain
    count, lab, st, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count < 2:
        raise PartRefusedError(_NO_PART, photo_u)
    warnings = [] if light_warning is None else [light_warning]
    if thin:
        warnings.append(f"{len(thin)} thin thing(s) apart from the part left out (a cable, a ruler, a "
                        "printed line, a sheet's edge)")
    if off_support:
        warnings.append(f"{len(off_support)} thing(s) apart from the board left out (a table's pattern, "
                        "an object beside it)")
    largest = int(np.max(st[1:, cv2.CC_STAT_AREA]))
    in_part = [j for j in range(1, count) if st[j, cv2.CC_STAT_AREA] >= _SECOND_PART * largest
               and near[lab == j].any()]
    if not in_part:
        # what differs at full size lies away from where the coarse photo found the part
        raise PartRefusedError("no part found on the support (nothing differs from the plate where the part "
                          "showed at a quarter of the size): a part of the support's colour needs a mat of "
                          "another colour under it, or light from another side", photo_u,
                          _blobs(labels, pieces, (w, h)))
    part = np.isin(lab, in_part).astype(np.uint8)
    # Where the support's pattern is broken near the part but no pixel differs enough (a face that
    # mirrors the board): the part reaches there too. A box's silhouette is convex: the outline is
    # then the hull of both.
    broken &= part == 0
    mirrored = int((broken | (part > plain)).sum()) > _MIRRORED * max(int(part.sum()), 1)
    if mirrored:
        part |= broken.astype(np.uint8)
        warnings.append("part of the part's outline was found only where it breaks the support's pattern "
                        "(a face mirroring the support, or alike it): the dimensions may be off")
    contours, _ = cv2.findContours(part, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if len(in_part) > 1 or mirrored:
        # Its pieces joined by their convex hull (a box's silhouette is convex), the hull's sides
        # sampled every pixel as an outline.
        every = np.vstack([c.reshape(-1, 2) for c in contours])
        hull = cv2.convexHull(every).reshape(-1, 2).astype(np.float64)
        contour = np.vstack([
            a + np.linspace(0, 1, max(2, int(np.linalg.norm(b - a))), endpoint=False)[:, None] * (b - a)
            for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True)])
        if len(in_part) > 1:
            warnings.append(f"the part's outline was found in {len(in_part)} pieces (a face's colour close "
                            "to the support's between them): joined as one box; the dimensions may be off")
    else:
        contour = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(np.float64)
    filled = np.zeros_like(part)
    cv2.drawContours(filled, [contour.astype(np.int32).reshape(-1, 1, 2)], -1, 1, thickness=-1)
    inside_roi = filled.astype(bool)
    # the RGB distance summed plane by plane over the window, then picked: numpy's norm over a last
    # axis of 3 of the part's pixels took 20-30 ms on a large part
    contrast = float(np.median(np.sqrt(norm2(planes(P - bg))[inside_roi])))
    if contrast < _LOW_CONTRAST:
        warnings.append(
            f"the part's colour is close to the support's (contrast {contrast:.0f} RGB levels, "
            f"under {_LOW_CONTRAST:.0f}): its outline may be wrong; a support of another colour helps"
        )
    inside = np.zeros((h, w), bool)
    inside[Y0:Y1, X0:X1] = inside_roi
    return Silhouette(
        contour=contour + np.array([X0, Y0], np.float64),
        mask=inside,
        contrast=contrast,
        area_px=int(inside_roi.sum()),
        warnings=warnings,
        difference=resid,
        origin=(X0, Y0),
        others=apart,
        tone=lut,
        shadow_least=float(shadow[0]),
        mirrored=mirrored,
    )

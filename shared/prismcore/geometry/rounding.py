"""The radius of a box's rounded edges, read from the shading across its fold edges.

Where two faces the camera sees meet (a fold), a rounded edge shows as a strip on either face in
which the surface turns from one face's normal to the other's: the shade ramps from one face's
level to the other's over about the radius. A silhouette edge (the face beyond it turned away)
tells less: it is cut off where the camera's ray grazes the rounding, which lies inside the sharp
outline by an amount that needs the radius (`model_error.rounding_shifts`). So the radius is read
at the folds and applied at the silhouettes; each fold's fit also says where its sharp edge lies
against the fold line the box was fitted to (an edge detector finds a ramp's steepest point).

The fold's cross-section is exact for a quarter-cylinder edge of radius r: with (m, n) along the
face toward its neighbour and along its normal, origin at the sharp edge, the arc point at angle
a (0: tangent to the face, 90 degrees: tangent to the neighbour) is seen at
s = r (1 - sin a - (1 - cos a) tan phi) inside the edge, phi the ray's angle from the face's
normal across the edge. Its Lambertian shade, ambient k0 plus k1 (normal . light), is
k0 (1 - cos a - sin a) + I_face cos a + I_neighbour sin a: linear in the flat levels and one
unknown. Per radius on a grid (and a blur and an offset of the fold of up to 3 px) that is a
linear least-squares fit of the luma profile across the fold (the median over positions along it,
so that print and texture mostly drop out); each face's level may drift linearly. The radius is
the folds' median, its uncertainty their spread (PER_FOLD_STD_MM for one fold). Without clear
evidence (RESOLVED_PX, MIN_SIGNIFICANCE) there is no estimate: blur, JPEG and print near a sharp
fold also look like a narrow ramp.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["RadiusEstimate", "estimate_edge_radius", "fold_profile_radius"]

_RADII_MM = np.linspace(0.0, 4.0, 41)  # candidate radii
_BLURS_PX = (0.7, 1.1, 1.6)  # candidate optical blur (Gaussian sigma, px)
_SHIFTS_PX = tuple(np.arange(-3.0, 3.01, 0.5))  # the sharp edge's offset from the fitted fold line
_HALF_WIDTH_MM = 6.5  # profile across the fold, each side
_STEP_PX = 0.25
_ALONG = np.linspace(0.15, 0.85, 41)  # positions along a fold (clear of the corners)
_ARC = np.linspace(0.0, math.pi / 2, 721)
_MIN_PX_PER_MM = 1.0  # coarser than this, a fold's ramp is not resolved
MIN_FOLDS = 1
"""Folds needed for an estimate (their spread is its uncertainty)."""
RESOLVED_PX = 3.2
"""The folds' ramps must span this many image px (their median) for a radius to be read: on
renders of sharp boxes (blur, JPEG, print near a fold; 12 photo-like and 20 of
benchmarks/accuracy.py) single folds' fitted ramps span up to 4.5 px, their median up to 3.1 px."""
MIN_SIGNIFICANCE = 2.0
"""A radius is read only when it is this many of its standard deviations above none."""
PER_FOLD_STD_MM = 0.5
"""1-sigma error of one fold's estimate (mm), on photo-like renders against their true radius:
print near a fold and a low contrast between the faces pull it either way."""
STD_FLOOR_MM = 0.15
"""Least 1-sigma of the estimate (mm): shading models of real surfaces are not exact."""


@dataclass(frozen=True)
class RadiusEstimate:
    """The edge radius read from the photo.

    radius_mm : float
        Best estimate, mm (0 for a sharp box).
    std_mm : float
        Its 1-sigma error, mm.
    per_fold_mm : tuple of float
        Each fold's own estimate.
    per_fold_px_per_mm : tuple of float
        Each fold's resolution: image px per mm across it on the more foreshortened face.
    """

    radius_mm: float
    std_mm: float
    per_fold_mm: tuple[float, ...]
    per_fold_px_per_mm: tuple[float, ...] = ()
    fold_offsets: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    """Per fold: its midpoint (3,) mm, and the image vector (2,) px from the fold line the box
    was fitted to (where `to_image` puts it) to where the shading puts the sharp edge."""


def _arc_table(tan_phi: float) -> tuple[np.ndarray, np.ndarray]:
    """The arc's in-face distance per unit radius, s / r = 1 - sin a - (1 - cos a) tan phi, over
    the arc angles a while it stays >= 0, in increasing order, and those angles."""
    h = 1 - np.sin(_ARC) - (1 - np.cos(_ARC)) * tan_phi  # decreasing in a while >= 0
    end = int(np.argmax(h < 0)) if np.any(h < 0) else _ARC.size
    end = max(end, 2)
    order = np.argsort(h[:end])
    return h[:end][order], _ARC[:end][order]


def _arcs(s: np.ndarray, radii: np.ndarray, tan_phi: float) -> np.ndarray:
    """`_arc_of` for every radius at once: (len(radii), len(s)); the table of the arc is the same
    for every radius (s scales with r), so one interpolation serves them all."""
    radii = np.asarray(radii, dtype=np.float64)
    out = np.zeros((radii.size, s.size))
    round_ = radii > 0
    if np.any(round_):
        table, angle = _arc_table(tan_phi)
        r = radii[round_, None]
        out[round_] = np.where(s >= r, 0.0, np.interp(s / r, table, angle))
    return out


def _arc_of(s: np.ndarray, r: float, tan_phi: float) -> np.ndarray:
    """Arc angle a (rad) seen at in-face distance s (mm) from the sharp edge; 0 where s >= r
    (flat face) and nan where the neighbour's side of the arc is seen (s < 0 there)."""
    out: np.ndarray = _arcs(np.asarray(s, dtype=np.float64), np.array([r]), tan_phi)[0]
    return out



def _gauss(sigma_px: float) -> np.ndarray:
    half = math.ceil(3.5 * sigma_px / _STEP_PX)
    x = np.arange(-half, half + 1) * _STEP_PX
    k = np.exp(-0.5 * (x / sigma_px) ** 2)
    out: np.ndarray = k / k.sum()
    return out


_CHUNK_VALUES = 1 << 21
"""The most float64 values one batch's largest array holds (16 MB): a sharp photo of a small part
has profiles of thousands of samples, and 123 candidates' designs at once took 740 MB."""


def _window_rss(columns: np.ndarray, starts: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares residual sums of squares of y by windows of columns.

    columns : (B, M, K) float64, K column signals of length M per batch entry;
    starts : (S,) int, window starts (each window M' = len(y) rows);
    y : (M', C). Returns (B, S): for each entry and start, the RSS of fitting y by
    columns[b, start:start + M']. See `_window_rss_t`.
    """
    return _window_rss_t(np.ascontiguousarray(np.asarray(columns).transpose(0, 2, 1)), starts, y)


def _window_rss_t(columns_t: np.ndarray, starts: np.ndarray, y: np.ndarray) -> np.ndarray:
    """`_window_rss` of columns given as (B, K, M), each column's signal contiguous.

    Each window's normal equations come from one product over the rows every window shares
    plus prefix sums over the few rows the offsets add, and a Cholesky solve vectorised over
    every window replaces a lstsq call per window; the residual is then computed itself: equal
    to `np.linalg.lstsq` to ~1e-14 on these well-conditioned designs, and lstsq itself is used
    for any ill-conditioned one. Entries are taken in chunks of bounded memory.
    """
    y = np.asarray(y, dtype=np.float64)  # a profile comes as float32: its sums need the digits
    b, k, m = columns_t.shape
    span = int(starts.max() - starts.min()) + 1
    per_entry = max(m * k, 2 * span * k * k, y.shape[0] * max(k, y.shape[1]))
    step = max(1, _CHUNK_VALUES // per_entry)
    return np.concatenate([_chunk_rss(columns_t[i:i + step], starts, y) for i in range(0, b, step)])


_PIVOT_LIMIT = 1e-6
"""A window whose Gram matrix has a Cholesky pivot under this share of its diagonal entry (a
column that the others explain to one part in a million; none of a fold's designs comes near)
is solved by lstsq itself: its normal equations would lose the digits that rank the candidates."""


def _window_grams(columns_t: np.ndarray, starts: np.ndarray, n: int) -> np.ndarray:
    """Gram matrices of every window [start, start + n) of `columns_t` (B, K, M): (B, S, K, K).

    The windows share their middle rows; that part is one product, and each window adds the
    rows before and after it (prefix sums of the few rows' outer products the offsets span)."""
    lo, hi = int(starts.min()), int(starts.max())
    if hi >= lo + n:  # windows that share nothing: each on its own
        return np.stack([w @ w.transpose(0, 2, 1) for w in (columns_t[..., s:s + n] for s in starts)], axis=1)
    core = columns_t[..., hi:lo + n]
    gram_core = core @ core.transpose(0, 2, 1)  # (B, K, K)
    b, k = columns_t.shape[:2]
    # head[:, i]: rows lo .. lo + i - 1 (window lo + i leaves them out); tail[:, i]: rows
    # lo + n .. lo + n + i - 1 (window lo + i adds them).
    head = np.zeros((b, hi - lo + 1, k, k))
    rows = columns_t[..., lo:hi].transpose(0, 2, 1)  # (B, hi - lo, K)
    np.cumsum(rows[..., :, None] * rows[..., None, :], axis=1, out=head[:, 1:])
    tail = np.zeros_like(head)
    rows = columns_t[..., lo + n:hi + n].transpose(0, 2, 1)
    np.cumsum(rows[..., :, None] * rows[..., None, :], axis=1, out=tail[:, 1:])
    offset = starts - lo
    out: np.ndarray = (gram_core + head[:, -1])[:, None] - head[:, offset] + tail[:, offset]
    return out


def _cholesky_solve(gram: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve gram @ x = rhs for a batch of small SPD matrices (..., K, K), (..., K, C) by a
    Cholesky factorisation vectorised over the batch; also returns which were ill-conditioned
    (a pivot under _PIVOT_LIMIT of its diagonal entry; their x is not to be used)."""
    k = gram.shape[-1]
    low = np.zeros_like(gram)
    ill = np.zeros(gram.shape[:-2], dtype=bool)
    for j in range(k):
        pivot = gram[..., j, j] - (low[..., j, :j] ** 2).sum(axis=-1)
        ill |= ~(pivot > _PIVOT_LIMIT * gram[..., j, j])
        d = np.sqrt(np.where(ill, 1.0, pivot))
        low[..., j, j] = d
        below = gram[..., j + 1:, j] - np.einsum("...ik,...k->...i", low[..., j + 1:, :j], low[..., j, :j])
        low[..., j + 1:, j] = below / d[..., None]
    z = np.empty_like(rhs)
    for j in range(k):  # forward: low z = rhs
        done = np.einsum("...k,...kc->...c", low[..., j, :j], z[..., :j, :])
        z[..., j, :] = (rhs[..., j, :] - done) / low[..., j, j, None]
    x = np.empty_like(rhs)
    for j in reversed(range(k)):  # back: low' x = z
        done = np.einsum("...k,...kc->...c", low[..., j + 1:, j], x[..., j + 1:, :])
        x[..., j, :] = (z[..., j, :] - done) / low[..., j, j, None]
    return x, ill


def _chunk_rss(columns_t: np.ndarray, starts: np.ndarray, y: np.ndarray) -> np.ndarray:
    n = y.shape[0]
    gram = _window_grams(columns_t, starts, n)  # (B, S, K, K)
    # Each window's design is a view into the columns: no copy of every window's rows.
    windows = [columns_t[..., start:start + n] for start in starts]  # S x (B, K, M')
    rhs = np.stack([w @ y for w in windows], axis=1)  # (B, S, K, C)
    coef, ill = _cholesky_solve(gram, rhs)
    # The residual itself, not y'y - b'coef: that difference keeps only ~1e-11 of the RSS.
    out = np.stack([((coef[:, j].transpose(0, 2, 1) @ w - y.T) ** 2).sum(axis=(1, 2))
                    for j, w in enumerate(windows)], axis=1)
    for b, s in zip(*np.nonzero(ill), strict=True):
        design = columns_t[b, :, starts[s]:starts[s] + n].T
        got, *_ = np.linalg.lstsq(design, y, rcond=None)
        out[b, s] = float(((design @ got - y) ** 2).sum())
    return out


def fold_profile_radius(profile: np.ndarray, x_px: np.ndarray, px_per_mm: tuple[float, float],
                        tan_phi: tuple[float, float]) -> tuple[float, float, np.ndarray]:
    """The radius that best explains one fold's shading profile.

    Parameters
    ----------
    profile : ndarray, shape (N, C)
        Image values across the fold at `x_px`, any number of channels.
    x_px : ndarray, shape (N,)
        Signed image distance (px) from the fold, uniform steps of _STEP_PX: negative on face A,
        positive on face B.
    px_per_mm : (g_a, g_b)
        Image px per mm across the fold on each face.
    tan_phi : (t_a, t_b)
        Tangent of the viewing ray's angle from each face's normal, across the fold (toward
        the other face).

    Returns
    -------
    radius_mm : float
    shift_px : float
        Where the sharp edge lies: at x = -shift_px.
    rss : ndarray, shape (len(_RADII_MM),)
        The best residual sum of squares per candidate radius (over blur and offset).
    """
    pad = math.ceil(3.5 * max(_BLURS_PX) / _STEP_PX) + math.ceil(max(_SHIFTS_PX) / _STEP_PX)
    fine = x_px[0] + _STEP_PX * np.arange(-pad, x_px.size + pad)
    on_a = fine < 0
    # Each face's level may drift across the profile (uneven light, vignetting): a slope each.
    slopes = np.stack([np.where(on_a, fine, 0.0), np.where(on_a, 0.0, fine)], axis=1) / x_px.size
    starts = pad + np.round(np.asarray(_SHIFTS_PX) / _STEP_PX).astype(int)
    # Every radius's three shading columns at once; the blurs as one filter each over all of
    # them (edge values repeated past the ends).
    a = _arcs(np.clip(-fine, 0, None) / px_per_mm[0], _RADII_MM, tan_phi[0])  # (radii, fine)
    b = _arcs(np.clip(fine, 0, None) / px_per_mm[1], _RADII_MM, tan_phi[1])
    turn = np.where(on_a, a, b)
    basis = np.stack([np.where(on_a, np.cos(a), np.sin(b)), np.where(on_a, np.sin(a), np.cos(b)),
                      1 - np.cos(turn) - np.sin(turn)], axis=1).reshape(-1, fine.size)  # (radii x 3, fine)
    # Every (blur, offset) pair of every radius solved at once: (radii x blurs, 5, fine) columns.
    columns_t = np.empty((_RADII_MM.size, len(_BLURS_PX), 5, fine.size))
    for i, sigma in enumerate(_BLURS_PX):
        blurred = cv2.sepFilter2D(basis, cv2.CV_64F, _gauss(sigma), np.ones(1),
                                  borderType=cv2.BORDER_REPLICATE)
        columns_t[:, i, :3] = blurred.reshape(_RADII_MM.size, 3, fine.size)
    columns_t[:, :, 3:] = slopes.T
    columns_t = columns_t.reshape(-1, 5, fine.size)
    n_pairs = len(_BLURS_PX) * len(_SHIFTS_PX)
    rss_all = np.empty((_RADII_MM.size, n_pairs))
    sharp = np.repeat(_RADII_MM == 0, len(_BLURS_PX))  # no turn: its third column is zero, left out
    rss_all[_RADII_MM == 0] = _window_rss_t(np.ascontiguousarray(columns_t[sharp][:, [0, 1, 3, 4]]), starts,
                                            profile).reshape(-1, n_pairs)
    rss_all[_RADII_MM != 0] = _window_rss_t(columns_t[~sharp], starts, profile).reshape(-1, n_pairs)
    pick = np.argmin(rss_all, axis=1)  # the first of equals, as the (blur, offset) order runs
    rss = rss_all[np.arange(_RADII_MM.size), pick]
    best_shift = np.asarray(_SHIFTS_PX)[pick % len(_SHIFTS_PX)]
    best = int(np.argmin(rss))
    return float(_RADII_MM[best]), float(best_shift[best]), rss


def _folds(size_mm: np.ndarray, camera_centre: np.ndarray
           ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Edges whose two faces both face the camera: (start, end, n_a, n_b) in world mm."""
    out = []
    for axis in range(3):
        j, k = (axis + 1) % 3, (axis + 2) % 3
        for vj in (0.0, size_mm[j]):
            for vk in (0.0, size_mm[k]):
                n_a, n_b = np.zeros(3), np.zeros(3)
                n_a[j] = 1.0 if vj else -1.0
                n_b[k] = 1.0 if vk else -1.0
                start = np.zeros(3)
                start[j], start[k] = vj, vk
                end = start.copy()
                end[axis] = size_mm[axis]
                if (camera_centre - start) @ n_a > 0 and (camera_centre - start) @ n_b > 0:
                    out.append((start, end, n_a, n_b))
    return out


_REMAP_MAX = 30_000
"""The most points one cv2.remap call samples (its maps' sides must stay under 32767)."""


def _sample(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear samples (..., C) float32 of `image` at image (x, y) points (..., 2)."""
    flat = pts.reshape(-1, 2).astype(np.float32)
    source = image.astype(np.float32)
    # remap's maps are images, whose sides OpenCV caps below 32767: sample in rows of that.
    chunks = [cv2.remap(source, part[:, 0].reshape(1, -1), part[:, 1].reshape(1, -1), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).reshape(part.shape[0], -1)
              for part in np.array_split(flat, max(1, -(-flat.shape[0] // _REMAP_MAX))) if len(part)]
    got = np.concatenate(chunks) if chunks else np.zeros((0, 1 if image.ndim == 2 else image.shape[2]),
                                                         np.float32)
    out: np.ndarray = got.reshape(*pts.shape[:-1], got.shape[-1])
    return out


def _luma(image: np.ndarray) -> np.ndarray:
    """(H, W, 1) float32 luma (or the single channel) of an image.

    Luma only: a JPEG keeps colour at half resolution, which would pass for a ramp."""
    if image.ndim == 2:
        return image[..., None]
    out: np.ndarray = image[..., :3].astype(np.float32) @ np.array([[0.299], [0.587], [0.114]], np.float32)
    return out


def _sample_luma(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """`_sample` of the image's luma at (x, y) points (..., 2): (..., 1) float32.

    Only the pixels the points reach are converted (a fold's strip, not the whole photo): the
    crop has one pixel beyond every point's bilinear neighbours, and where it meets the photo's
    border the border is the photo's, so the samples are those of the whole photo's luma."""
    h, w = image.shape[:2]
    flat = pts.reshape(-1, 2)
    if flat.size == 0 or not np.all(np.isfinite(flat)):
        return _sample(_luma(image), pts)
    x0 = int(np.clip(np.floor(flat[:, 0].min()) - 1, 0, w - 1))
    x1 = int(np.clip(np.ceil(flat[:, 0].max()) + 2, x0 + 1, w))
    y0 = int(np.clip(np.floor(flat[:, 1].min()) - 1, 0, h - 1))
    y1 = int(np.clip(np.ceil(flat[:, 1].max()) + 2, y0 + 1, h))
    return _sample(_luma(image[y0:y1, x0:x1]), pts - np.array([x0, y0], dtype=pts.dtype))


def _no_radius_whatever_follows(ramps_px: list[float], left: int) -> bool:
    """Whether the folds' ramps read so far (px) already give no radius, whatever the `left`
    folds still to read show: even were each of them kept with the widest ramp, the median
    ramp would stay under RESOLVED_PX (a fold read later can only lower it or leave it)."""
    if len(ramps_px) + left < MIN_FOLDS:
        return True
    if not ramps_px:
        return False
    return float(np.median([*ramps_px, *([math.inf] * left)])) < RESOLVED_PX


def estimate_edge_radius(image: np.ndarray, to_image: Callable[[np.ndarray], np.ndarray],
                         size_mm: np.ndarray, camera_centre_mm: np.ndarray) -> RadiusEstimate | None:
    """The box's edge radius from the shading across its fold edges.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The photo as taken.
    to_image : callable
        World points (N, 3) mm (box from (0, 0, 0) to `size_mm`) -> image (x, y) px as
        photographed (lens distortion included), (N, 2).
    size_mm : ndarray, shape (3,)
        The box's extent along X, Y, Z, mm.
    camera_centre_mm : ndarray, shape (3,)
        The camera's centre in the same frame.

    Returns
    -------
    RadiusEstimate or None
        None when there is no evidence of a rounding (the caller keeps its prior): fewer than
        MIN_FOLDS folds seen large enough to read, their ramps spanning less than RESOLVED_PX
        (median over folds), or a radius under MIN_SIGNIFICANCE standard deviations.
    """
    size = np.asarray(size_mm, dtype=np.float64)
    centre = np.asarray(camera_centre_mm, dtype=np.float64)
    radii: list[float] = []
    resolution: list[float] = []
    offsets: list[tuple[np.ndarray, np.ndarray]] = []
    readable = []
    for start, end, n_a, n_b in _folds(size, centre):
        mid = (start + end) / 2
        p0 = to_image(mid[None])[0]
        g = tuple(float(np.linalg.norm(to_image((mid - n)[None])[0] - p0)) for n in (n_b, n_a))
        if min(g) >= _MIN_PX_PER_MM:
            readable.append((start, end, n_a, n_b, mid, p0, g))
    def ramps_px() -> list[float]:
        return [r * q for r, q in zip(radii, resolution, strict=True)]

    for done, (start, end, n_a, n_b, mid, p0, g) in enumerate(readable):
        if _no_radius_whatever_follows(ramps_px(), len(readable) - done):
            return None  # the folds read so far decide it: no need to read the others
        ray = centre - mid
        tan_phi = (float(ray @ n_b / (ray @ n_a)), float(ray @ n_a / (ray @ n_b)))
        x = np.arange(-_HALF_WIDTH_MM * g[0], _HALF_WIDTH_MM * g[1], _STEP_PX)
        s = np.where(x < 0, -x / g[0], x / g[1])
        # World points: along the fold, then into face A (away from B's normal) or face B.
        into = np.where((x < 0)[:, None], -n_b, -n_a)
        along = start + _ALONG[:, None] * (end - start)
        world = along[:, None, :] + s[None, :, None] * into[None, :, :]
        pts = to_image(world.reshape(-1, 3)).reshape(_ALONG.size, x.size, 2)
        profile = np.median(_sample_luma(image, pts), axis=0)
        r, shift, _ = fold_profile_radius(profile, x, g, tan_phi)  # type: ignore[arg-type]
        if r >= _RADII_MM[-1]:
            continue  # the widest ramp tried: something else (print, a shadow), not a rounding
        radii.append(r)
        toward_b = to_image((mid - n_a)[None])[0] - p0
        offsets.append((mid, -shift * toward_b / np.linalg.norm(toward_b)))
        resolution.append(min(g))
    if _no_radius_whatever_follows(ramps_px(), 0):
        return None  # too few folds, or ramps what a sharp fold's blur, JPEG and print also show
    spread = float(np.std(radii, ddof=1)) if len(radii) > 1 else 0.0
    std = max(spread, PER_FOLD_STD_MM / math.sqrt(len(radii)), STD_FLOOR_MM)
    if float(np.median(radii)) < MIN_SIGNIFICANCE * std:
        return None  # the folds disagree too much to tell a rounding from none
    return RadiusEstimate(float(np.median(radii)), std, tuple(radii), tuple(resolution), tuple(offsets))

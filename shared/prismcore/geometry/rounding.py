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
from scipy import ndimage

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


def _arc_of(s: np.ndarray, r: float, tan_phi: float) -> np.ndarray:
    """Arc angle a (rad) seen at in-face distance s (mm) from the sharp edge; 0 where s >= r
    (flat face) and nan where the neighbour's side of the arc is seen (s < 0 there)."""
    if r <= 0:
        return np.zeros_like(s)
    sa = r * (1 - np.sin(_ARC) - (1 - np.cos(_ARC)) * tan_phi)  # decreasing in a while >= 0
    end = int(np.argmax(sa < 0)) if np.any(sa < 0) else _ARC.size
    end = max(end, 2)
    order = np.argsort(sa[:end])
    a = np.interp(s, sa[:end][order], _ARC[:end][order])
    return np.where(s >= r, 0.0, a)


def _gauss(sigma_px: float) -> np.ndarray:
    half = math.ceil(3.5 * sigma_px / _STEP_PX)
    x = np.arange(-half, half + 1) * _STEP_PX
    k = np.exp(-0.5 * (x / sigma_px) ** 2)
    out: np.ndarray = k / k.sum()
    return out


_COND_LIMIT = 1e6
"""A design matrix this ill-conditioned (none of a fold's is past 300) is solved by lstsq itself:
its normal equations would lose the digits that rank the candidates."""


_CHUNK_VALUES = 1 << 21
"""The most float64 values one batch's largest array holds (16 MB): a sharp photo of a small part
has profiles of thousands of samples, and 123 candidates' designs at once took 740 MB."""


def _window_rss(columns: np.ndarray, starts: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares residual sums of squares of y by windows of columns.

    columns : (B, M, K) float64, K column signals of length M per batch entry;
    starts : (S,) int, window starts (each window M' = len(y) rows);
    y : (M', C). Returns (B, S): for each entry and start, the RSS of fitting y by
    columns[b, start:start + M']. The normal equations' sums come from prefix sums (every
    window at once) and one batched solve replaces a lstsq call per window: equal to
    `np.linalg.lstsq` to ~1e-14 on these well-conditioned designs, and lstsq itself is used
    for any ill-conditioned one. Entries are taken in chunks of bounded memory.
    """
    y = np.asarray(y, dtype=np.float64)  # a profile comes as float32: its sums need the digits
    b, m, k = columns.shape
    per_entry = max(m * k * k, starts.size * y.shape[0] * max(k, y.shape[1]))
    step = max(1, _CHUNK_VALUES // per_entry)
    return np.concatenate([_chunk_rss(columns[i:i + step], starts, y) for i in range(0, b, step)])


def _chunk_rss(columns: np.ndarray, starts: np.ndarray, y: np.ndarray) -> np.ndarray:
    n = y.shape[0]
    outer = np.einsum("bmk,bml->bmkl", columns, columns)
    prefix = np.concatenate([np.zeros_like(outer[:, :1]), np.cumsum(outer, axis=1)], axis=1)
    del outer
    gram = prefix[:, starts + n] - prefix[:, starts]  # (B, S, K, K)
    del prefix
    eig = np.linalg.eigvalsh(gram)
    ill = eig[..., 0] <= eig[..., -1] / _COND_LIMIT ** 2
    gram[ill] = np.eye(gram.shape[-1])  # solved below by lstsq; a singular one would stop solve
    designs = columns[:, starts[:, None] + np.arange(n)]  # (B, S, M', K)
    coef = np.linalg.solve(gram, np.einsum("bsnk,nc->bskc", designs, y))  # (B, S, K, C)
    # The residual itself, not y'y - b'coef: that difference keeps only ~1e-11 of the RSS.
    out: np.ndarray = ((np.einsum("bsnk,bskc->bsnc", designs, coef) - y) ** 2).sum(axis=(2, 3))
    for b, s in zip(*np.nonzero(ill), strict=True):
        design = columns[b, starts[s]:starts[s] + n]
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
    arcs = [(_arc_of(np.clip(-fine, 0, None) / px_per_mm[0], float(r), tan_phi[0]),
             _arc_of(np.clip(fine, 0, None) / px_per_mm[1], float(r), tan_phi[1])) for r in _RADII_MM]
    a, b = np.array([x for x, _ in arcs]), np.array([x for _, x in arcs])  # (radii, fine)
    turn = np.where(on_a, a, b)
    basis = np.stack([np.where(on_a, np.cos(a), np.sin(b)), np.where(on_a, np.sin(a), np.cos(b)),
                      1 - np.cos(turn) - np.sin(turn)], axis=-1)  # (radii, fine, 3)
    # Every (blur, offset) pair of every radius solved at once: (radii x blurs, fine, 5) columns.
    columns = np.concatenate([
        np.concatenate([ndimage.convolve1d(basis, _gauss(sigma), axis=1, mode="nearest"),
                        np.broadcast_to(slopes, (*basis.shape[:2], 2))], axis=-1)[:, None]
        for sigma in _BLURS_PX], axis=1).reshape(-1, fine.size, 5)
    n_pairs = len(_BLURS_PX) * len(_SHIFTS_PX)
    rss_all = np.empty((_RADII_MM.size, n_pairs))
    sharp = np.repeat(_RADII_MM == 0, len(_BLURS_PX))  # no turn: its third column is zero, left out
    rss_all[_RADII_MM == 0] = _window_rss(columns[sharp][..., [0, 1, 3, 4]], starts,
                                          profile).reshape(-1, n_pairs)
    rss_all[_RADII_MM != 0] = _window_rss(columns[~sharp], starts, profile).reshape(-1, n_pairs)
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
    # Luma only: a JPEG keeps colour at half resolution, which would pass for a ramp.
    img = image[..., None] if image.ndim == 2 else (image[..., :3].astype(np.float32)
                                                    @ np.array([[0.299], [0.587], [0.114]], np.float32))
    size = np.asarray(size_mm, dtype=np.float64)
    centre = np.asarray(camera_centre_mm, dtype=np.float64)
    radii: list[float] = []
    resolution: list[float] = []
    offsets: list[tuple[np.ndarray, np.ndarray]] = []
    for start, end, n_a, n_b in _folds(size, centre):
        mid = (start + end) / 2
        ray = centre - mid
        tan_phi = (float(ray @ n_b / (ray @ n_a)), float(ray @ n_a / (ray @ n_b)))
        p0 = to_image(mid[None])[0]
        g = tuple(float(np.linalg.norm(to_image((mid - n)[None])[0] - p0)) for n in (n_b, n_a))
        if min(g) < _MIN_PX_PER_MM:
            continue
        x = np.arange(-_HALF_WIDTH_MM * g[0], _HALF_WIDTH_MM * g[1], _STEP_PX)
        s = np.where(x < 0, -x / g[0], x / g[1])
        # World points: along the fold, then into face A (away from B's normal) or face B.
        into = np.where((x < 0)[:, None], -n_b, -n_a)
        along = start + _ALONG[:, None] * (end - start)
        world = along[:, None, :] + s[None, :, None] * into[None, :, :]
        pts = to_image(world.reshape(-1, 3)).reshape(_ALONG.size, x.size, 2)
        profile = np.median(_sample(img, pts), axis=0)
        r, shift, _ = fold_profile_radius(profile, x, g, tan_phi)  # type: ignore[arg-type]
        if r >= _RADII_MM[-1]:
            continue  # the widest ramp tried: something else (print, a shadow), not a rounding
        radii.append(r)
        toward_b = to_image((mid - n_a)[None])[0] - p0
        offsets.append((mid, -shift * toward_b / np.linalg.norm(toward_b)))
        resolution.append(min(g))
    if len(radii) < MIN_FOLDS:
        return None
    if float(np.median([r * g for r, g in zip(radii, resolution, strict=True)])) < RESOLVED_PX:
        return None  # what a sharp fold's blur, JPEG and print near it also show
    spread = float(np.std(radii, ddof=1)) if len(radii) > 1 else 0.0
    std = max(spread, PER_FOLD_STD_MM / math.sqrt(len(radii)), STD_FLOOR_MM)
    if float(np.median(radii)) < MIN_SIGNIFICANCE * std:
        return None  # the folds disagree too much to tell a rounding from none
    return RadiusEstimate(float(np.median(radii)), std, tuple(radii), tuple(resolution), tuple(offsets))

"""Zero-click: a box's second face proposed from one face found and the photo's line segments.

A face's region does not close when the fold to its neighbour is between two faces of nearly
the same shade, when its far side meets a background of its own colour, or when it is a thin
sliver; the face beside it is then found alone. Its neighbour across one of its four sides is
pinned down by three directions (as CubeSLAM's cuboid proposals are):

1. the shared side's own direction: the far side passes through the vanishing point of the
   found face's side and the side opposite it;
2. the box's third direction: the two sides leaving the shared side's corners, from the long
   line segments that start at (or point back to) those corners, away from the face;
3. how far the face reaches: along those two rays, the line through the first vanishing point
   where the colour changes most strongly across it.

The proposals are only seeds: `locate` places the corners with the engine's edge fit and its
box fit, and its PnP screen, fit guards and confidence accept or refuse them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["across_samples", "propose_neighbours"]

_NEAR_LINE_PX = 4.0  # work px: a segment's line passes this close to a corner it leaves
_MIN_SEG_PX = 6.0  # work px: shorter segments are texture
_MERGE_DEG = 3.0  # directions this close at one corner are one ray
_RAYS = 3  # rays kept per corner
_MIN_TURN_DEG = 4.0  # a ray this close to a side of the face (or its extension) is that side
_MIN_REACH_PX = 4.0  # work px: the thinnest sliver proposed
_MIN_CORNER_DEG = 15.0  # a proposed face's sides leave the shared side at least this steeply
_MAX_SPREAD_DEG = 25.0  # the two rays toward one vanishing point part at most this much
# Or meet ahead at any angle short of a right one: a top face seen from little above it, its
# sides converging toward a vanishing point close by, shows them up to 87 deg apart (clutter
# scenes 71, 128 and 135: 87, 62 and 57 deg); `_plausible`'s convexity keeps the far side short
# of where they meet, and the PnP screen and the fit judge the box.
_MAX_MEET_DEG = 90.0


def _unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / np.linalg.norm(v), dtype=np.float64)


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    """Angle (0-90 deg) between the lines along u and v."""
    c = abs(float(u @ v)) / float(np.linalg.norm(u) * np.linalg.norm(v))
    return math.degrees(math.acos(min(1.0, c)))


def _rays(corner: np.ndarray, outward: np.ndarray, along: np.ndarray, adjacent: np.ndarray,
          segments: np.ndarray, reach: float) -> list[tuple[np.ndarray, float]]:
    """Directions (unit, work px) leaving `corner` away from the face, with their support
    (total length of the segments along them), strongest first.

    A segment counts when its line passes within _NEAR_LINE_PX of the corner, it lies on the
    face's outer side, its nearer end is within `reach` of the corner, and it is not along the
    shared side or the face's other side at that corner.
    """
    p, q = segments[:, :2], segments[:, 2:]
    d = q - p
    length = np.linalg.norm(d, axis=1)
    normal = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
    off = np.abs(((corner - p) * normal).sum(axis=1))
    dp, dq = np.linalg.norm(p - corner, axis=1), np.linalg.norm(q - corner, axis=1)
    near_end, far_end = np.minimum(dp, dq), np.where(dp < dq, 1, 0)
    far_pt = np.where(far_end[:, None] == 0, p, q)
    out_far = (far_pt - corner) @ outward
    out_near = (np.where(far_end[:, None] == 0, q, p) - corner) @ outward
    keep = ((off < _NEAR_LINE_PX + 0.03 * length) & (near_end < reach) & (out_far > 3.0)
            & (out_near > -3.0) & (length >= _MIN_SEG_PX))
    found: list[tuple[np.ndarray, float]] = []
    for k in np.flatnonzero(keep):
        u = _unit(far_pt[k] - corner)
        if _angle_deg(u, along) < _MIN_TURN_DEG or _angle_deg(u, adjacent) < _MIN_TURN_DEG:
            continue
        weight = float(length[k])
        for i, (v, w) in enumerate(found):
            if _angle_deg(u, v) < _MERGE_DEG and u @ v > 0:
                found[i] = (_unit(v * w + u * weight), w + weight)
                break
        else:
            found.append((u, weight))
    found.sort(key=lambda item: -item[1])
    return found[:_RAYS]


def across_samples(grad: tuple[np.ndarray, np.ndarray], a: np.ndarray, b: np.ndarray,
                   samples: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """The colour change across each segment a[i]-b[i] (a, b: (m, 2)) at `samples` points of
    its middle 80 %: the gradient's component along the segment's normal, summed over the
    channels, the best of three offsets (the segment may lie a pixel off the edge).

    Returns
    -------
    (ndarray (m, samples) float64, ndarray (m,) bool)
        The samples (clipped to the image) and whether each segment lies inside it.
    """
    gx, gy = grad
    h, w = gx.shape[:2]
    # Gathered by flat pixel index (several times faster than indexing by (y, x) pairs).
    flat_x, flat_y = gx.reshape(h * w, -1), gy.reshape(h * w, -1)
    d = b - a
    length = np.maximum(np.linalg.norm(d, axis=1), 1e-6)
    n = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
    t = np.linspace(0.1, 0.9, samples)[None, :, None]
    base = a[:, None] + t * d[:, None]
    best = np.zeros(base.shape[:2])
    inside = np.ones(len(a), dtype=bool)
    for o in (-1.0, 0.0, 1.0):
        xy = np.rint(base + o * n[:, None]).astype(np.intp)
        x, y = xy[..., 0], xy[..., 1]
        inside &= ((x >= 0) & (y >= 0) & (x < w) & (y < h)).all(axis=1)
        at = np.minimum(np.maximum(y, 0), h - 1) * w + np.minimum(np.maximum(x, 0), w - 1)
        change = (np.take(flat_x, at, axis=0) * n[:, None, 0, None]
                  + np.take(flat_y, at, axis=0) * n[:, None, 1, None])  # (m, samples, channels)
        # The channels' sum written out: a reduction over that short last axis cost more.
        across = np.abs(change[..., 0])
        for c in range(1, change.shape[-1]):
            across += np.abs(change[..., c])
        best = np.maximum(best, across)
    return best, inside


def _supports(grad: tuple[np.ndarray, np.ndarray], a: np.ndarray, b: np.ndarray,
              samples: int = 24) -> np.ndarray:
    """(m,): mean colour change across each segment a[i]-b[i] (`across_samples`); 0 outside
    the image."""
    best, inside = across_samples(grad, a, b, samples)
    return np.where(inside, best.mean(axis=1), 0.0)


def _hom(p: np.ndarray) -> np.ndarray:
    return np.array([p[0], p[1], 1.0])


def _profile(grad: tuple[np.ndarray, np.ndarray], origin: np.ndarray, u: np.ndarray,
             steps: int) -> np.ndarray:
    """(steps,): colour change across the ray origin + i u (i = 0, 1, ...; u a unit vector),
    the best of three offsets across it; 0 outside the image."""
    gx, gy = grad
    h, w = gx.shape[:2]
    n = np.array([-u[1], u[0]])
    base = origin + np.arange(steps)[:, None] * u
    best = np.zeros(steps)
    for o in (-1.0, 0.0, 1.0):
        xy = np.rint(base + o * n).astype(int)
        inside = (xy >= 0).all(axis=1) & (xy[:, 0] < w) & (xy[:, 1] < h)
        x, y = np.clip(xy[:, 0], 0, w - 1), np.clip(xy[:, 1], 0, h - 1)
        across = np.abs(gx[y, x] * n[0] + gy[y, x] * n[1]).sum(axis=-1)
        best = np.maximum(best, np.where(inside, across, 0.0))
    return best


def _along(profile: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Mean of `profile` over [lo, hi) for each pair (integer-rounded, at least one sample)."""
    total = np.concatenate([[0.0], np.cumsum(profile)])
    lo = np.clip(np.rint(lo).astype(int), 0, len(profile) - 1)
    hi = np.clip(np.maximum(np.rint(hi).astype(int), lo + 1), 1, len(profile))
    return np.asarray((total[hi] - total[lo]) / (hi - lo), dtype=np.float64)


def _far_side(a: np.ndarray, ua: np.ndarray, b: np.ndarray, ub: np.ndarray, vp: np.ndarray,
              grad: tuple[np.ndarray, np.ndarray], t_max: float
              ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The far corners on the rays a + t ua and b + s ub whose side (a line through the
    vanishing point `vp`, homogeneous) lies on a strong colour change, with the rays' own
    colour change up to it and none past it (a label's border parallel to the far side has the
    box's edges running on past it), and that score."""
    t = np.arange(_MIN_REACH_PX, min(t_max, _exit(a, ua, grad[0].shape)), 1.0)
    ka = a + t[:, None] * ua
    far = np.cross(np.column_stack([ka, np.ones(len(t))]), vp)
    x = np.cross(far, np.cross(_hom(b), _hom(b + ub)))
    ok = np.abs(x[:, 2]) > 1e-9
    kb = x[:, :2] / np.where(ok, x[:, 2], 1.0)[:, None]
    s = (kb - b) @ ub
    ok &= (s >= _MIN_REACH_PX) & (s <= 1.5 * t_max)
    if not ok.any():
        return None
    t, s, ka, kb = t[ok], s[ok], ka[ok], kb[ok]
    steps = int(1.5 * max(t.max(), s.max())) + 8
    pa, pb = _profile(grad, a, ua, steps), _profile(grad, b, ub, steps)
    inside = np.sqrt(_along(pa, 0.1 * t, 0.9 * t) * _along(pb, 0.1 * s, 0.9 * s))
    past = np.maximum(_along(pa, t + 2, 1.3 * t + 6) / np.maximum(_along(pa, 0.1 * t, 0.9 * t), 1e-6),
                      _along(pb, s + 2, 1.3 * s + 6) / np.maximum(_along(pb, 0.1 * s, 0.9 * s), 1e-6))
    across = _supports(grad, ka, kb, 12)
    score = across * inside * (1.0 - 0.7 * np.clip(past, 0.0, 1.0))
    i = int(np.argmax(score))
    return ka[i], kb[i], float(score[i])


def _profiles(grad: tuple[np.ndarray, np.ndarray], origins: np.ndarray, u: np.ndarray,
              steps: int) -> np.ndarray:
    """(m, steps): `_profile` from each of origins (m, 2) along its unit vector u[i] (m, 2)."""
    gx, gy = grad
    h, w = gx.shape[:2]
    n = np.column_stack([-u[:, 1], u[:, 0]])
    base = origins[:, None] + np.arange(steps)[None, :, None] * u[:, None]
    best = np.zeros(base.shape[:2])
    for o in (-1.0, 0.0, 1.0):
        xy = np.rint(base + o * n[:, None]).astype(int)
        inside = (xy >= 0).all(axis=2) & (xy[..., 0] < w) & (xy[..., 1] < h)
        x, y = np.clip(xy[..., 0], 0, w - 1), np.clip(xy[..., 1], 0, h - 1)
        change = gx[y, x] * n[:, None, 0, None] + gy[y, x] * n[:, None, 1, None]  # (m, samples, 3)
        # The channels' sum written out: a reduction over that short last axis cost more.
        across = np.abs(change[..., 0]) + np.abs(change[..., 1]) + np.abs(change[..., 2])
        best = np.maximum(best, np.where(inside, across, 0.0))
    return best


def _ended(profile: np.ndarray, length: np.ndarray) -> np.ndarray:
    """For each length L: the mean colour change along the first L px of a side (its middle
    80 %) less for any change running on past L (a side ends at its corner; a label's border
    or a ray's guess does not)."""
    inside = _along(profile, 0.1 * length, length)
    past = _along(profile, length + 1, 1.2 * length + 4) / np.maximum(inside, 1e-6)
    return np.asarray(inside * (1.0 - 0.7 * np.clip(past, 0.0, 1.0)), dtype=np.float64)


def _exit(p: np.ndarray, u: np.ndarray, shape: tuple[int, ...]) -> float:
    """How far (px) the ray p + t u runs inside an image of this (h, w)."""
    h, w = shape[:2]
    out = math.inf
    for axis, size in ((0, w), (1, h)):
        if u[axis] > 1e-9:
            out = min(out, (size - 1 - p[axis]) / u[axis])
        elif u[axis] < -1e-9:
            out = min(out, -p[axis] / u[axis])
    return max(out, 0.0)


def _meet_ahead(a: np.ndarray, ua: np.ndarray, b: np.ndarray, ub: np.ndarray) -> bool:
    """Whether the rays a + t ua and b + s ub meet at t, s > 0."""
    m = np.column_stack([ua, -ub])
    if abs(np.linalg.det(m)) < 1e-12:
        return False
    t, s = np.linalg.solve(m, b - a)
    return bool(t > 0 and s > 0)


def _one_ray(a: np.ndarray, ua: np.ndarray, b: np.ndarray, vp: np.ndarray,
             grad: tuple[np.ndarray, np.ndarray], t_max: float
             ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The far corners when a ray leaves corner a only (the other side is faint, or the
    segments missed it): the far side is where the ray a + t ua ends with the line through the
    vanishing point `vp` starting on a colour change there; the other far corner where that
    line's change ends, on a line from b."""
    t = np.arange(_MIN_REACH_PX, min(t_max, _exit(a, ua, grad[0].shape)), 2.0)
    if len(t) == 0:
        return None
    ka = a + t[:, None] * ua
    toward = vp[:2][None] - ka * vp[2] if abs(vp[2]) > 1e-12 else np.broadcast_to(vp[:2], ka.shape)
    toward = toward / np.maximum(np.linalg.norm(toward, axis=1), 1e-12)[:, None]
    toward *= np.sign(toward @ (b - a))[:, None]
    side = float(np.linalg.norm(b - a))
    near = max(int(0.5 * side), 8)  # px of the far side that certainly lie on the face
    pa = _profile(grad, a, ua, int(1.5 * t_max) + 8)
    # Every other px of the far side is enough to tell an edge from none.
    far = _profiles(grad, ka, 2.0 * toward, near // 2).mean(axis=1)
    score = far * _ended(pa, t)
    i = int(np.argmax(score))
    ka_i, u_far = ka[i], toward[i]
    s = np.arange(0.3 * side, 1.7 * side, 1.0)
    pf = _profile(grad, ka_i, u_far, int(2.3 * side) + 8)
    kb = ka_i + s[:, None] * u_far
    from_b = _supports(grad, np.broadcast_to(b, kb.shape), kb)
    # The side from b is faint (no segment found it) or runs into other edges: where the far
    # side ends is the better clue.
    j = int(np.argmax(_ended(pf, s) * (from_b > 0)))
    if score[i] <= 0 or from_b[j] <= 0:
        return None
    return ka_i, kb[j], float(_supports(grad, ka_i[None], kb[j][None])[0] * math.sqrt(
        _ended(pa, t[i:i + 1])[0] * from_b[j]))


def _plausible(quad: np.ndarray, shape: tuple[int, int]) -> bool:
    """A face: convex, inside the image, its far side neither a point nor far longer than the
    side it shares (perspective does not shrink or stretch a rectangle's side that much)."""
    h, w = shape
    if not ((quad >= 0).all() and (quad[:, 0] <= w - 1).all() and (quad[:, 1] <= h - 1).all()):
        return False
    edges = np.roll(quad, -1, axis=0) - quad
    turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    if not ((turns > 0).all() or (turns < 0).all()):
        return False
    shared, far = np.linalg.norm(quad[3] - quad[0]), np.linalg.norm(quad[2] - quad[1])
    if not 0.33 * shared <= far <= 3.0 * shared:
        return False
    # The sides leaving the shared side turn away from it (a box's fold and the edges leaving
    # it are never nearly one line in the photo) and the face has some width.
    fold = quad[3] - quad[0]
    normal = np.array([-fold[1], fold[0]]) / shared
    reach = np.abs([(quad[1] - quad[0]) @ normal, (quad[2] - quad[3]) @ normal])
    return bool(reach.min() >= _MIN_REACH_PX and _angle_deg(quad[1] - quad[0], fold) >= _MIN_CORNER_DEG
                and _angle_deg(quad[2] - quad[3], fold) >= _MIN_CORNER_DEG)


def propose_neighbours(face: np.ndarray, segments: np.ndarray, grad: tuple[np.ndarray, np.ndarray],
                       shape: tuple[int, int]) -> list[tuple[np.ndarray, float]]:
    """The faces that may lie beside `face`, one per side of it at most.

    Parameters
    ----------
    face : ndarray, shape (4, 2)
        A face's corners, image (x, y) work px, in order around it.
    segments : ndarray, shape (n, 4)
        Line segments (x0, y0, x1, y1), work px.
    grad : (ndarray, ndarray)
        x and y derivatives of the work image, each (h, w, channels) float32.
    shape : (int, int)
        The work image's (h, w).

    Returns
    -------
    list of (ndarray (4, 2), float)
        Each proposed face's corners (the shared side's two corners and the far two) and its
        score (colour change across its far side times that along its rays), best first.
    """
    h, w = shape
    centre = face.mean(axis=0)
    sides = np.linalg.norm(np.roll(face, -1, axis=0) - face, axis=1)
    out: list[tuple[np.ndarray, float]] = []
    for k in range(4):
        a, b = face[k], face[(k + 1) % 4]
        c, d = face[(k + 2) % 4], face[(k + 3) % 4]
        along = b - a
        normal = _unit(np.array([-along[1], along[0]]))
        if normal @ (centre - a) > 0:
            normal = -normal
        vp = np.cross(np.cross(_hom(a), _hom(b)), np.cross(_hom(d), _hom(c)))
        reach = 0.35 * float(sides[k]) + 6.0
        rays_a = _rays(a, normal, along, a - d, segments, reach)
        rays_b = _rays(b, normal, along, b - c, segments, reach)
        if not rays_a and not rays_b:
            continue
        t_max = min(4.0 * float(sides.max()), float(math.hypot(w, h)))
        best: tuple[np.ndarray, float] | None = None
        if not (rays_a and rays_b):
            # A ray found at one corner only: the other side's far corner from where the far
            # side's colour change ends.
            if rays_a:
                got = _one_ray(a, rays_a[0][0], b, vp, grad, t_max)
                if got is not None:
                    best = (np.array([a, got[0], got[1], b]), got[2])
            else:
                got = _one_ray(b, rays_b[0][0], a, vp, grad, t_max)
                if got is not None:
                    best = (np.array([a, got[1], got[0], b]), got[2])
        for ua, _ in rays_a if rays_b else []:
            for ub, _ in rays_b:
                if ua @ ub <= 0 or _angle_deg(ua, ub) > (_MAX_MEET_DEG if _meet_ahead(a, ua, b, ub)
                                                         else _MAX_SPREAD_DEG):
                    continue
                pair = _far_side(a, ua, b, ub, vp, grad, t_max)
                if pair is not None and (best is None or pair[2] > best[1]):
                    best = (np.array([a, pair[0], pair[1], b]), pair[2])
        if best is not None and _plausible(best[0], (h, w)):
            out.append(best)
    out.sort(key=lambda item: -item[1])
    return out

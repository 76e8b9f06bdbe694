"""The lens distortion a photo's own edges show: a one-coefficient radial model read from how a
box's straight edges bend (plumb-line method), combined with what phones' lenses do before the
photo is looked at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

__all__ = ["DISTORTED_SHARE", "DISTORTION_PRIOR", "RadialDistortion", "estimate_distortion", "tls_line"]

DISTORTION_PRIOR = 0.06
"""1-sigma of a phone lens's radial distortion before the photo is looked at, as the fraction q by
which it moves a point at the image's corner radius (k1 of -0.15..0.10 at focal lengths 0.7-1.2
times the width moves the corners by about -12 % .. +8 %)."""
DISTORTED_SHARE = 0.5
"""Prior probability that a photo still carries its lens's distortion (many phones remove it in
the camera, many do not)."""


@dataclass(frozen=True)
class RadialDistortion:
    """A one-coefficient radial lens model in pixels: a pinhole point p lands at
    c + (p - c) (1 + kappa |p - c|^2) (OpenCV's k1 is kappa * f^2).

    kappa : float, px^-2
    kappa_std : float, px^-2, its 1-sigma error
    centre : ndarray, shape (2,), the distortion centre (the principal point), px
    """

    kappa: float
    kappa_std: float
    centre: np.ndarray

    def distort(self, pts: np.ndarray) -> np.ndarray:
        """Pinhole image points (N, 2) px -> where the lens puts them."""
        d = np.asarray(pts, dtype=np.float64) - self.centre
        moved: np.ndarray = self.centre + d * (1 + self.kappa * (d**2).sum(axis=-1, keepdims=True))
        return moved

    def undistort(self, pts: np.ndarray) -> np.ndarray:
        """Image points (N, 2) px as photographed -> where a pinhole puts them."""
        return _undistort(np.asarray(pts, dtype=np.float64), self.centre, self.kappa)


def _undistort(pts: np.ndarray, centre: np.ndarray, kappa: float) -> np.ndarray:
    d = pts - centre
    r2d = (d**2).sum(axis=-1, keepdims=True)
    scale = np.ones_like(r2d)
    # r_d = r_u (1 + kappa r_u^2): fixed point in the scale r_u / r_d (contracts for |kappa r^2| < 1/3).
    for _ in range(12):
        scale = 1.0 / (1.0 + kappa * r2d * scale**2)
    undone: np.ndarray = centre + d * scale
    return undone


def _tls_cost(pts: np.ndarray) -> float:
    """Sum of squared distances of points (N, 2) to their total-least-squares line."""
    d = pts - pts.mean(axis=0)
    return float(np.linalg.eigvalsh(d.T @ d)[0])


def _tls_costs(pts: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """`_tls_cost` of every edge at once: the edges' points (N, 2) one after another, each
    edge from its index in `starts` to the next's. The smallest eigenvalue of each edge's 2x2
    scatter matrix as LAPACK's dlaev2 takes it (the determinant over the largest, no
    cancellation on a straight edge)."""
    counts = np.diff(np.append(starts, len(pts)))
    means = np.add.reduceat(pts, starts, axis=0) / counts[:, None]
    d = pts - np.repeat(means, counts, axis=0)
    a = np.add.reduceat(d[:, 0] * d[:, 0], starts)
    b = np.add.reduceat(d[:, 0] * d[:, 1], starts)
    c = np.add.reduceat(d[:, 1] * d[:, 1], starts)
    big = 0.5 * ((a + c) + np.hypot(a - c, 2 * b))
    safe = np.where(big > 0, big, 1.0)
    small: np.ndarray = np.where(big > 0, (np.maximum(a, c) / safe) * np.minimum(a, c) - (b / safe) * b, 0.0)
    return small


def tls_line(pts: np.ndarray) -> np.ndarray:
    """The (a, b, c) line, (a, b) a unit normal, nearest to the points (N, 2) in total least squares."""
    m = pts.mean(axis=0)
    d = pts - m
    normal = np.linalg.eigh(d.T @ d)[1][:, 0]
    return np.array([normal[0], normal[1], -float(normal @ m)])


def estimate_distortion(samples: list[np.ndarray], centre: np.ndarray, radius_px: float) -> RadialDistortion:
    """Radial lens distortion read from how the box's straight edges bend (plumb-line method).

    The box's edges are straight in the world, so under a pinhole they are straight in the
    image; the one-coefficient radial model's kappa is chosen to make the undistorted samples of
    every edge as straight as possible (sum of squared distances to each edge's own line).
    Its error follows from that cost's curvature and the samples' scatter about their lines;
    the estimate is then combined with the prior: with probability DISTORTED_SHARE the photo
    still carries distortion of 1-sigma DISTORTION_PRIOR, else none (the camera removed it). An
    edge set that says little (short edges near the centre) leaves the lens undistorted with the
    prior's error, a long bent edge overrules it.

    Parameters
    ----------
    samples : list of ndarray, shape (N_i, 2)
        Image (x, y) px along each straight edge, as photographed (`EdgeFit.points`).
    centre : ndarray, shape (2,)
        Distortion centre (the principal point), px.
    radius_px : float
        The image's corner radius (half its diagonal), px: the prior is stated there.

    Returns
    -------
    RadialDistortion
    """
    from scipy.optimize import minimize_scalar

    centre = np.asarray(centre, dtype=np.float64)
    unit = 1.0 / radius_px**2  # kappa per unit of q
    prior = DISTORTION_PRIOR
    edges = [np.asarray(e, dtype=np.float64) for e in samples if e is not None and len(e) >= 6]
    if not edges:
        return RadialDistortion(0.0, prior * unit, centre)
    # Work in units of the corner radius: the cost is then of order one per edge.
    # Every edge's samples in one array, undistorted at once (one fixed point, not one per edge).
    scaled = (np.concatenate(edges) - centre) / radius_px
    starts = np.cumsum([0] + [len(e) for e in edges[:-1]])
    zero = np.zeros(2)

    def cost(q: float) -> float:
        return float(_tls_costs(_undistort(scaled, zero, q), starts).sum())

    bound = 0.35  # past this the fixed point stops contracting at the corners
    q_hat = float(minimize_scalar(cost, bounds=(-bound, bound), method="bounded",
                                  options={"xatol": 1e-5}).x)
    n = len(scaled)
    dof = n - 2 * len(edges) - 1
    if dof <= 0:
        return RadialDistortion(0.0, prior * unit, centre)
    h = 1e-3
    per_edge = np.array([_tls_costs(_undistort(scaled, zero, q), starts)
                         for q in (q_hat - h, q_hat, q_hat + h)])
    curv = (per_edge[0] - 2 * per_edge[1] + per_edge[2]) / h**2
    grad = (per_edge[2] - per_edge[0]) / (2 * h)
    if not curv.sum() > 0:
        return RadialDistortion(0.0, prior * unit, centre)
    # From the samples' scatter about their lines (all samples independent) ...
    var = 2 * (per_edge[1].sum() / dof) / curv.sum()
    # ... and from how far the edges disagree (leave one edge out: jackknife). Each edge's own q
    # (one Newton step from the common one) carries what bends that edge alone (texture,
    # shading, a compressed video's blocks, a face fitted in part), which neighbouring samples
    # share; one edge that alone says "bent" must not decide. The larger of the two.
    ok = curv > 0
    if ok.sum() >= 3:
        c, q_own = curv[ok], q_hat - grad[ok] / curv[ok]
        left_out = (c @ q_own - c * q_own) / (c.sum() - c)
        m = len(c)
        var = max(var, float((m - 1) / m * ((left_out - left_out.mean()) ** 2).sum()))
    # The prior is a mixture: many cameras already remove their lens's distortion from the JPEG
    # (q = 0 exactly, probability 1 - DISTORTED_SHARE), the others' q ~ N(0, prior^2). The
    # posterior is then a point mass at 0 and a normal, and its median is the estimate: exactly
    # 0 while the bend is one the samples' noise explains (an undistorted photo is left as it
    # was), the normal's own estimate for a clear bend, and continuous in the data in between
    # (a thresholding estimator: neighbouring photos get neighbouring answers).
    post_var = 1.0 / (1.0 / var + 1.0 / prior**2)
    q_post = q_hat * post_var / var
    log_bf = 0.5 * (np.log(var / (var + prior**2)) + q_hat**2 / var - q_hat**2 / (var + prior**2))
    odds = DISTORTED_SHARE / (1 - DISTORTED_SHARE) * np.exp(min(log_bf, 50.0))
    w = odds / (1 + odds)
    sd = float(np.sqrt(post_var))
    below = w * float(ndtr(-q_post / sd))  # the posterior's mass below 0
    if below > 0.5:
        q = q_post + sd * float(ndtri(0.5 / w))
    elif below + 1 - w < 0.5:
        q = q_post + sd * float(ndtri(1 - 0.5 / w))
    else:
        q = 0.0
    q_var = w * (post_var + (q_post - q) ** 2) + (1 - w) * q**2  # the posterior's spread about q
    return RadialDistortion(q * unit, float(np.sqrt(q_var)) * unit, centre)

"""One focal length for the photos that share a camera: pooled from each photo's own fit.

Each photo of a box fitted without a known focal length gives an estimate with a standard
error; a video's frames, or a batch's photos with the same EXIF camera, were all taken with one
focal length (one zoom setting). Pooling them gives a value far steadier than any one frame's,
which then measures every frame (a second, cheap pass: only the fit, not the scan, depends on it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from prismcore.scan.focal import PooledFocal
from prismcore.scan.pipeline import plan_scan
from prismcore.spec import ScanSpec

__all__ = ["PooledFocal", "focal_estimate", "pool_focal"]

_OUTLIER_SIGMAS = 3.0
_MAD_TO_SIGMA = 1.4826  # the MAD of a normal distribution, in sigmas


def pool_focal(estimates: Sequence[tuple[float, float]]) -> PooledFocal | None:
    """Pool per-photo focal estimates of one camera robustly.

    Parameters
    ----------
    estimates : sequence of (focal_px, std_px)
        Each photo's fitted focal length and its standard error, px. Non-finite or non-positive
        entries are ignored.

    Returns
    -------
    PooledFocal or None
        None when no usable estimate is given.
    """
    f = np.array([e[0] for e in estimates], dtype=np.float64)
    s = np.array([e[1] for e in estimates], dtype=np.float64)
    ok = np.isfinite(f) & np.isfinite(s) & (f > 0) & (s > 0)
    index = np.flatnonzero(ok)
    if index.size == 0:
        return None
    f, s = f[ok], s[ok]
    centre = float(np.median(f))
    scatter = _MAD_TO_SIGMA * float(np.median(np.abs(f - centre)))
    # An estimate is an outlier when it is far from the median by its own error and by how much
    # the estimates scatter anyway (a frame whose fit went wrong claims a small error).
    keep = np.abs(f - centre) <= _OUTLIER_SIGMAS * np.sqrt(s**2 + scatter**2) + 1e-9
    f, s, index = f[keep], s[keep], index[keep]
    w = 1.0 / s**2
    mean = float(np.sum(w * f) / np.sum(w))
    std = float(1.0 / math.sqrt(np.sum(w)))
    if f.size > 1:
        chi2 = float(np.sum(w * (f - mean) ** 2)) / (f.size - 1)
        std *= math.sqrt(max(1.0, chi2))
    return PooledFocal(mean, std, tuple(int(i) for i in index))


def focal_estimate(spec: ScanSpec, image: np.ndarray) -> tuple[float, float] | None:
    """One photo's own fitted focal length and its standard error (px), for pooling; None when
    the photo gives none (a focal length known already, too few points, a fit refused).

    image : (H, W, 3) RGB, as for `prismcore.plan_scan`. Only the fit runs, not the scan.
    """
    from prismcore.errors import InputError

    try:
        camera = plan_scan(spec, image).camera
    except InputError:
        return None
    if camera.get("focal_source") != "fitted" or camera.get("focal_std_px") is None:
        return None
    return float(camera["focal_px"]), float(camera["focal_std_px"])

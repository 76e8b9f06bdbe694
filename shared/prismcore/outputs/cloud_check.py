"""The check every point-cloud writer (CSV, PLY, LAS/LAZ) applies to its arrays, in one place."""

from __future__ import annotations

from typing import Any

import numpy as np

from prismcore.errors import InputError

__all__ = ["check_cloud"]


def check_cloud(points: Any, colors: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """The one check every cloud writer applies: `points` (N, 3) float32/float64, finite;
    `colors` None or (N, 3) uint8, one per point. Returns them unchanged or raises InputError."""
    if not isinstance(points, np.ndarray):
        raise InputError(f"points must be a numpy array, got {type(points).__name__}")
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {points.shape}")
    if points.dtype not in (np.float32, np.float64):
        raise InputError(f"points must be float32 or float64, got {points.dtype}")
    if len(points) and not (np.isfinite(points.min()) and np.isfinite(points.max())):
        bad = ~np.isfinite(points)
        row = int(np.argmax(bad.any(axis=1)))
        raise InputError(
            f"points hold {int(bad.sum())} non-finite values (NaN or inf), the first in row "
            f"{row}: {points[row].tolist()}"
        )
    if colors is None:
        return points, None
    if not isinstance(colors, np.ndarray):
        raise InputError(f"colors must be a numpy array or None, got {type(colors).__name__}")
    if colors.ndim != 2 or colors.shape[1] != 3:
        raise InputError(f"colors must have shape (N, 3), got {colors.shape}")
    if colors.dtype != np.uint8:
        raise InputError(f"colors must be uint8, got {colors.dtype}")
    if len(colors) != len(points):
        raise InputError(
            f"colors has shape {colors.shape} but points has shape {points.shape}: "
            "one colour per point is needed"
        )
    return points, colors

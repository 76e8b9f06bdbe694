"""The pixel scan of one face, expressible over row bands (tiles) that merge exactly.

A :class:`FacePlan` is fixed before any tile runs (the region, the seed colour); each tile
scans rows ``[r0, r1)`` of the plan's window independently; stacking the tiles' masks in row
order gives exactly the whole-window result. That is what lets the worker scan tiles in parallel.

Methods
-------
paper
    The paper's colour scan: each row of the marked rectangle is walked left to right; a pixel
    within +-tolerance (every RGB channel) of the current colour scale stays in it, a pixel
    outside opens a new scale at its own colour. A pixel belongs to the object when its scale's
    colour is within +-tolerance of the seed (the colour of the first pixel of the region).
    Each row starts in the seed's scale, so rows are independent.
default
    Every pixel whose centre lies inside the face quad located by sub-pixel edge fitting:
    print, labels, lighting and noise inside the face cannot punch holes, and the background
    cannot leak in, because the boundary comes from the face's straight edges.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["FacePlan", "FaceScan", "merge_bands", "row_tiles", "scan_band"]


@dataclass(frozen=True)
class FacePlan:
    """What a tile needs to scan its rows of one face.

    Attributes
    ----------
    name : str
        "front" or "side".
    image : int
        Index of the image the face is in (0 front photo, 1 side photo).
    region : ndarray, shape (4, 2)
        Object polygon (TL, TR, BR, BL), image (x, y) px.
    marked : ndarray, shape (4, 2)
        The region the user marked; point loss is counted against it.
    window : tuple of int
        (row0, row1, col0, col1): the half-open pixel window the scan covers.
    method : str
    seed : tuple of float or None
        Seed colour (R, G, B) of the paper method.
    tolerance : float
    """

    name: str
    image: int
    region: np.ndarray
    marked: np.ndarray
    window: tuple[int, int, int, int]
    method: str
    seed: tuple[float, float, float] | None
    tolerance: float


@dataclass(frozen=True)
class FaceScan:
    """Merged scan of one face: boolean masks over the plan's window, shape (rows, cols)."""

    plan: FacePlan
    object_mask: np.ndarray
    marked_mask: np.ndarray

    @property
    def point_loss_counts(self) -> tuple[int, int]:
        """(rejected, marked) pixel counts."""
        marked = int(self.marked_mask.sum())
        return int((self.marked_mask & ~self.object_mask).sum()), marked


def window_for(quads: list[np.ndarray], shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    """Smallest pixel window holding every pixel centre of the quads, clipped to the image."""
    pts = np.concatenate(quads)
    row0 = max(0, int(np.ceil(pts[:, 1].min())))
    row1 = min(shape[0], int(np.floor(pts[:, 1].max())) + 1)
    col0 = max(0, int(np.ceil(pts[:, 0].min())))
    col1 = min(shape[1], int(np.floor(pts[:, 0].max())) + 1)
    return row0, row1, col0, col1


def row_tiles(plan: FacePlan, count: int) -> list[tuple[int, int]]:
    """Split the plan's window rows into at most `count` bands (row offsets within the window)."""
    rows = plan.window[1] - plan.window[0]
    edges = np.linspace(0, rows, min(max(count, 1), max(rows, 1)) + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges) if b > a]


def polygon_mask(quad: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Pixels (rows x cols) whose centres lie inside a convex clockwise quad (edges included)."""
    y = rows.astype(np.float64)
    lo = np.full(y.shape, -np.inf)
    hi = np.full(y.shape, np.inf)
    for i in range(4):
        (vx, vy), (wx, wy) = quad[i], quad[(i + 1) % 4]
        # Inside means (wx-vx)*(y-vy) - (wy-vy)*(x-vx) >= 0: a bound on x for each row.
        ex, ey = wx - vx, wy - vy
        rhs = ex * (y - vy)
        if ey > 0:
            hi = np.minimum(hi, vx + rhs / ey)
        elif ey < 0:
            lo = np.maximum(lo, vx + rhs / ey)
        else:
            hi = np.where(rhs >= 0, hi, -np.inf)
    eps = 1e-9
    return (cols[None, :] >= lo[:, None] - eps) & (cols[None, :] <= hi[:, None] + eps)


def paper_colour_scan(pixels: np.ndarray, seed: np.ndarray, tolerance: float) -> np.ndarray:
    """The paper's left-to-right colour-scale scan of each row.

    Parameters
    ----------
    pixels : ndarray, shape (rows, cols, 3)
        RGB, 0-255 units (any real dtype).
    seed : ndarray, shape (3,)
        Colour of the object's scale.
    tolerance : float
        Per-channel tolerance, 0-255 units.

    Returns
    -------
    ndarray of bool, shape (rows, cols)
        True where the pixel's colour scale is the object's.
    """
    # The scale recurrence runs along each row, so it is vectorised across rows instead.
    cols_first = np.ascontiguousarray(np.swapaxes(pixels.astype(np.float32), 0, 1))
    seed = seed.astype(np.float32)
    seed_like = (np.abs(cols_first - seed) <= tolerance).all(axis=2)
    ref = np.broadcast_to(seed, cols_first.shape[1:]).copy()
    is_object = np.ones(cols_first.shape[1], dtype=bool)
    out = np.empty(cols_first.shape[:2], dtype=bool)
    for x in range(cols_first.shape[0]):
        column = cols_first[x]
        opened = (np.abs(column - ref) > tolerance).any(axis=1)
        ref[opened] = column[opened]
        is_object[opened] = seed_like[x, opened]
        out[x] = is_object
    return out.T


def scan_band(image: np.ndarray, plan: FacePlan, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
    """Scan rows ``[r0, r1)`` of the plan's window.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        The RGB image the face is in.

    Returns
    -------
    object_mask, marked_mask : ndarray of bool, shape (r1 - r0, window cols)
    """
    row0, _, col0, col1 = plan.window
    rows = np.arange(row0 + r0, row0 + r1)
    cols = np.arange(col0, col1)
    marked = polygon_mask(plan.marked, rows, cols)
    if plan.method == "paper":
        assert plan.seed is not None
        pixels = image[rows[0] : rows[-1] + 1, col0:col1] if rows.size else image[:0, col0:col1]
        found = paper_colour_scan(pixels, np.asarray(plan.seed), plan.tolerance) & marked
    else:
        found = polygon_mask(plan.region, rows, cols)
    return found, marked


def merge_bands(plan: FacePlan, bands: list[tuple[np.ndarray, np.ndarray]]) -> FaceScan:
    """Stack tile results (in row order) into the face's scan."""
    cols = plan.window[3] - plan.window[2]
    objects = [b[0] for b in bands] or [np.zeros((0, cols), dtype=bool)]
    marked = [b[1] for b in bands] or [np.zeros((0, cols), dtype=bool)]
    return FaceScan(plan, np.concatenate(objects), np.concatenate(marked))

"""Hand-held: the table around the board, modelled from the photo itself.

A part lying on a board bigger than it, seen from low, rises past the board's far edge in the
photo: there its outline lies against the table, which no plate shows. The table's look without
the part is read from the photo's own surroundings: its colour, median-filtered over a window
wider than the part (a median keeps a table's or a paper's straight edges and ignores a blob
that fills under half its window), the board's area filled with the table's colour around it
first so the median near the board's edge is the table's. The board's edge itself is modelled as
the photo shows it: a pixel there mixes the board's pattern and the table by the part of it the
board covers. What the table's texture leaves over (grain, streaks) is noise the segmentation
measures; a part whose colour is the table's is flagged there as on the board.
"""

from __future__ import annotations

from typing import cast

import cv2
import numpy as np

from prismcore.station.boxfit import project
from prismcore.station.segment import SHADOW_RANGE, difference2, norm2, planes, shadow_ratio

__all__ = ["TABLE_HEIGHT", "board_cover", "shadow_difference", "smooth_level", "table_zone", "with_table"]

_COARSE = 4  # the table's level is found in a photo this many times smaller
TABLE_HEIGHT = 0.5  # the table is modelled where a part this tall (of the board's longer side) can show
_MEDIAN = 0.35  # the median's window, of the board's longer side in the photo
_TEXTURE = 3.0  # the table's texture reaches this many times its local median difference


def board_cover(corners_px: np.ndarray, shape: tuple[int, int], blur_px: float = 0.7) -> np.ndarray:
    """The share (float32, 0..1) of each pixel the board covers: its four corners (4, 2) image
    (x, y) px, convex, in order round it; the edge blurred as the photo's is."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    centre = corners_px.mean(axis=0)
    inside = np.full((h, w), np.inf, np.float32)
    for a, b in zip(corners_px, np.roll(corners_px, -1, axis=0), strict=True):
        n = np.array([a[1] - b[1], b[0] - a[0]], np.float64) / max(float(np.linalg.norm(b - a)), 1e-9)
        if n @ (centre - a) < 0:
            n = -n  # towards the board's inside
        d = (xs - np.float32(a[0])) * np.float32(n[0]) + (ys - np.float32(a[1])) * np.float32(n[1])
        np.minimum(inside, d, out=inside)
    cover = np.clip(inside + 0.5, 0.0, 1.0).astype(np.float32)
    return cast("np.ndarray", cv2.GaussianBlur(cover, (0, 0), blur_px)) if blur_px > 0 else cover


def table_zone(corners_mm: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, height_mm: float
               ) -> np.ndarray:
    """Where a part standing on the board, up to `height_mm` tall, can show in the photo: the
    convex hull (M, 2) px of the board's corners (4, 2) mm and the same corners raised by that
    height (towards the camera's side of the board: z negative), through K, R, t (board -> camera).
    The table in front of the board, where no part on it shows, is left out."""
    base = np.column_stack([corners_mm, np.zeros(len(corners_mm))])
    X = np.vstack([base, base - np.array([0.0, 0.0, height_mm])])
    X = X[(X @ R.T + t)[:, 2] > 1.0]  # a raised corner behind the camera: left out
    return cast("np.ndarray", cv2.convexHull(project(X, K, R, t).astype(np.float32)).reshape(-1, 2)
                .astype(np.float64))


def smooth_level(P: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """Normalised convolution: the weighted (`weight` (H, W)) mean colour of `P` (H, W, 3) near
    each pixel (Gaussian, `sigma` px), computed on a copy reduced to a few pixels a sigma (a light
    or a table's colour varies slowly) and brought back up; where no weight lies near, the mean
    over four times as wide. (H, W, 3) float32."""
    h, w = weight.shape
    f = float(min(1.0, 3.0 / sigma))
    small = (max(1, round(w * f)), max(1, round(h * f)))
    Ps = cv2.resize(P * weight[..., None], small, interpolation=cv2.INTER_AREA)
    Ws = cv2.resize(weight, small, interpolation=cv2.INTER_AREA)
    s = sigma * f
    num, den = cv2.GaussianBlur(Ps, (0, 0), s), cv2.GaussianBlur(Ws, (0, 0), s)
    far, far_den = cv2.GaussianBlur(Ps, (0, 0), 4 * s), cv2.GaussianBlur(Ws, (0, 0), 4 * s)
    near = num / np.maximum(den, 1e-6)[..., None]
    wide = far / np.maximum(far_den, 1e-6)[..., None]
    level = np.where((den > 0.05)[..., None], near, wide).astype(np.float32)
    return cast("np.ndarray", cv2.resize(level, (w, h), interpolation=cv2.INTER_LINEAR))


def with_table(
    photo_u: np.ndarray, board_plate: np.ndarray, cover: np.ndarray, zone_px: np.ndarray
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The support as it would look without the part, the board's model (`board_plate`, valid
    where `cover` > 0) joined to the table's read from the photo round the board.

    Returns (plate (H, W, 3) uint8, known (H, W) bool: where the support is modelled, the board
    and the table within `zone_px` (a convex polygon, :func:`table_zone`); elsewhere the photo;
    warnings: a fallback that may change the outline, said).
    """
    h, w = photo_u.shape[:2]
    small = (max(1, w // _COARSE), max(1, h // _COARSE))
    P = cv2.resize(photo_u, small, interpolation=cv2.INTER_AREA).astype(np.float32)
    on_board = cv2.resize(cover, small, interpolation=cv2.INTER_AREA) > 0.02
    on_board = cv2.dilate(on_board.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    ys, xs = np.nonzero(on_board)
    if len(xs) == 0:
        return board_plate, cover > 0.5, [
            "the board's area in the photo is under a pixel at a quarter of the size: no table is "
            "modelled round it, a part rising past the board is refused"]
    extent = float(max(xs.max() - xs.min(), ys.max() - ys.min()) + 1)
    # The board's area filled with the table's colour nearby (normalised convolution).
    fill = smooth_level(P, (~on_board).astype(np.float32), max(2.0, 0.1 * extent))
    filled = np.where(on_board[..., None], fill, P)
    k = int(max(5, round(_MEDIAN * extent))) | 1
    k = min(k, 2 * (min(small) // 2) - 1)
    level = cv2.medianBlur(np.clip(filled, 0, 255).astype(np.uint8), k) if k >= 3 else filled.astype(np.uint8)
    zone = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(zone, np.round(zone_px).astype(np.int32).reshape(-1, 1, 2), 1)
    known = zone.astype(bool) | (cover > 0.5)
    plate = photo_u.copy()
    bx, by, bw, bh = cv2.boundingRect(known.astype(np.uint8))
    if bw == 0:
        return plate, known, []
    # Only the known area's box is modelled at full size (elsewhere the plate is the photo), on
    # whole coarse pixels so that the texture's amplitude is measured as over the whole photo.
    y0, x0 = by // _COARSE * _COARSE, bx // _COARSE * _COARSE
    y1, x1 = (min(n, -(-end // _COARSE) * _COARSE) for end, n in ((by + bh, h), (bx + bw, w)))
    win = (slice(y0, y1), slice(x0, x1))
    level_full = cv2.resize(level, (w, h), interpolation=cv2.INTER_LINEAR)[win].astype(np.float32)
    Pw = photo_u[win].astype(np.float32)
    table_plate = _texture_allowed(Pw, level_full, k, cover[win] > 0.02)
    c = cover[win][..., None]
    inside = c * board_plate[win].astype(np.float32) + (1 - c) * table_plate
    plate[win] = np.where(known[win][..., None], np.clip(inside, 0, 255), Pw).astype(np.uint8)
    return plate, known, []


def _texture_allowed(P: np.ndarray, level: np.ndarray, k: int, board: np.ndarray) -> np.ndarray:
    """The table's level with its own texture let through: each pixel's difference from the level
    (after the shadow's scale, as the segmentation compares: :func:`shadow_scale`) shortened by
    the texture's local amplitude (its median over `k` pixels of a quarter-size copy), so the
    table's grain and streaks differ from the plate by nothing while a part differs by all but
    that amplitude. P, level: (H, W, 3) float32; board: (H, W) bool, the board's area (its
    difference is the board's, not the table's texture)."""
    s = _shadow_scale(P, level)
    r = P - np.minimum(s * level, 255.0)
    D = np.sqrt(norm2(planes(r)))
    # the texture's amplitude: the local median of the difference (a part filling under half the
    # window leaves it), _TEXTURE times over
    small = (max(1, P.shape[1] // _COARSE), max(1, P.shape[0] // _COARSE))
    Dc = cv2.resize(D, small, interpolation=cv2.INTER_AREA)
    # the board differs from the table's level by all its contrast: its pixels are no texture (the
    # median's window over the board's edge took the board's difference for the table's grain,
    # and a part rising past the board passed as grain)
    board_c = cv2.resize(board.astype(np.float32), small, interpolation=cv2.INTER_AREA) > 0.02
    if (~board_c).any():
        Dc[board_c] = float(np.median(Dc[~board_c]))
    kk = min(k, max(1, 2 * (min(small) // 2) - 1))
    amp = (cv2.medianBlur(np.clip(Dc, 0, 255).astype(np.uint8), kk) if kk >= 3 else Dc).astype(np.float32)
    A = cv2.resize(amp * _TEXTURE, (P.shape[1], P.shape[0]), interpolation=cv2.INTER_LINEAR)
    keep = np.minimum(1.0, A / np.maximum(D, 1e-6))[..., None]
    return cast("np.ndarray", np.minimum(s * level, 255.0) + r * keep)


def _shadow_scale(P: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """(H, W, 1): the scale of `bg` nearest `P` at each pixel, within SHADOW_RANGE (as
    segment.difference2 finds it)."""
    return cast("np.ndarray", np.clip(shadow_ratio(planes(P), planes(bg)), *SHADOW_RANGE)[..., None])


def shadow_difference(P: np.ndarray, bg: np.ndarray,
                      shadow: tuple[np.ndarray | float, np.ndarray | float] = SHADOW_RANGE) -> np.ndarray:
    """(H, W) float32: the distance (RGB levels) of `P` from `bg` (H, W, 3) scaled as a shadow
    scales it (within `shadow`: the least and the most, numbers or (H, W) arrays), as the
    segmentation measures it."""
    b = planes(bg.astype(np.float32))
    d2 = difference2(planes(P.astype(np.float32)), b, norm2(b), shadow)
    return cast("np.ndarray", np.sqrt(d2, out=d2))

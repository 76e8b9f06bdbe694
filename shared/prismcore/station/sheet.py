"""The printed sheet round a hand-held board: how far its white paper reaches past the board on
each side, and the ink printed on it.

`prism board` prints the board on a page with a margin, a check ruler and a line of text; other
printers, "fit to page" and trimmed sheets change that margin, so it is read from the photo, not
taken from the layout. Without it the paper round the board was modelled as the table (a median
of the photo round the board): the sheet's edge, its ruler and its text then differed from that
model and were found as parts, and a part standing on the margin was refused as reaching past
the board.
"""

from __future__ import annotations

from typing import cast

import cv2
import numpy as np

from prismcore.station.board import BoardSpec, board_image

__all__ = ["MAX_MARGIN_MM", "ink_strokes", "sheet_margins"]

MAX_MARGIN_MM = 60.0
"""The widest margin looked for on a side (an A3 page round a small board leaves more: the rest is
modelled as the table)."""
_PX_PER_MM = 2.0  # the sheet is read from the photo rectified onto the board's plane at this scale
_STEP_MM = 0.5
_FIRST_MM = 1.0  # the board's edge blurred in the photo: the paper is looked for from here out
_LEAST_MM = 2.0  # a margin narrower than this is none (the board's own edge, blurred)
_INK_MM = 1.5  # strokes thinner than this on the paper are its print: a ruler, its ticks, text
_PAPER_LIGHT = 0.88  # paper: within this share of the white squares' light near that side, or its
# inverse (a metal table mirroring a lamp is brighter than paper, a grey one darker)...
_PAPER_HUE = 0.06  # ...and its colour's direction within this of theirs (a table is seldom as grey)
_LAG_MM = 2.0  # outward, paper is judged against the paper this far before it (a sheet's edge is sharper)
_SOFT_STEP = 0.08  # ...changed by no more than this share of it (a soft light's fall is gentler)
_SOFT_LEAST = 0.5  # ...and a soft shadow darkens it to this share of the white squares' light at most
_STARTS = 0.3  # a side shows paper where this share of its positions do next to the board
_GONE_MM = 2.0  # the paper ends where lines this deep in a row are not paper
_EDGE_STEP = 0.04  # ... and its colour steps by this share of the white's light across that end
_NO_END = 0.7  # a side whose paper never ends (in view) at this share of its positions is a light
# table (a part as light as paper standing on the margin hides the paper's end at fewer)...
_LEAVES = 0.8  # ...unless this share of those positions' paper runs out of the photo: paper to its edge


def _hue(rgb: np.ndarray) -> np.ndarray:
    return cast("np.ndarray", rgb / (np.linalg.norm(rgb, axis=-1, keepdims=True) + 1.0))


def _paper(lines: np.ndarray, ok: np.ndarray, level: np.ndarray, lag: int) -> np.ndarray:
    """Where each position's line (positions, distance out, 3) shows paper, (positions, distance)
    bool: paper of the white squares' colour (`level`, (3,)), as light as they are at the board's
    edge, then, outward, as light as the paper `lag` steps before it on the same line (each
    averaged over `lag` steps: a photo's noise), and no darker than _SOFT_LEAST of them. Soft
    light (an area light, a window, the part's own shadow) darkens or lightens the margin
    smoothly away from the board, past a fixed share of the white's light, while the sheet's
    edge is a step within `lag`: read against the white squares' light alone, a margin in a soft
    shadow, or lit more than the board's middle, ended a millimetre out, was modelled as the
    table, and was found as part. Its colour is the white squares' in any light, so a table as
    light as the paper but of another colour is no paper however gradually it comes."""
    light = np.linalg.norm(lines, axis=-1)
    white = float(np.linalg.norm(level))
    paper: np.ndarray = (ok & (np.linalg.norm(_hue(lines) - _hue(level), axis=-1) <= _PAPER_HUE)
                         & (light >= _SOFT_LEAST * white))
    paper[:, :lag] &= (light[:, :lag] >= _PAPER_LIGHT * white) & (light[:, :lag] <= white / _PAPER_LIGHT)
    mean = cv2.blur(light.astype(np.float32), (lag, 1), borderType=cv2.BORDER_REPLICATE)
    ref = np.full(len(lines), white, np.float32)
    for d in range(lag, lines.shape[1]):
        ref = np.where(paper[:, d - lag], mean[:, d - lag], ref)
        paper[:, d] &= np.abs(mean[:, d] - ref) <= _SOFT_STEP * ref
    return paper


def sheet_margins(
    photo_u: np.ndarray, board: BoardSpec, pose_h: np.ndarray
) -> tuple[float, float, float, float]:
    """How far the white paper reaches past each side of the board, mm: (left, top, right, bottom)
    in the board's own frame (x along its squares_x, y along squares_y).

    Parameters
    ----------
    photo_u : (H, W, 3) uint8
        The undistorted photo.
    board : BoardSpec
    pose_h : (3, 3) float64
        Board mm -> undistorted photo px.

    Returns
    -------
    tuple of 4 float
        Each side's margin, mm: 0 where no paper shows past the board (a board cut to its squares,
        or that side out of view) or where what looks like paper does not end within
        `MAX_MARGIN_MM` (a light table, a large sheet: modelled as the table).

    Notes
    -----
    The photo is rectified onto the board's plane, strokes under `_INK_MM` (the ruler, the text)
    closed over. Along each side, a pixel is paper where it is as light as the white squares near
    that side and of their colour; each position's paper ends where `_GONE_MM` in a row is seen
    and not paper (the photo's edge is no end). The side's margin is the commonest end (a part or
    its shadow ends some positions early), kept where the colour steps by `_EDGE_STEP` of the
    white's light across it and most positions' paper ends within `MAX_MARGIN_MM`.
    """
    bw, bh = board.size_mm
    m = MAX_MARGIN_MM
    q = _PX_PER_MM
    size = (round((bw + 2 * m) * q), round((bh + 2 * m) * q))
    # rectified pixel (i, j) centre -> board mm ((i + 0.5) / q - m, ...)
    to_board = np.array([[1 / q, 0, 0.5 / q - m], [0, 1 / q, 0.5 / q - m], [0, 0, 1.0]])
    to_photo = pose_h @ to_board
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    rect = cv2.warpPerspective(photo_u, to_photo, size, flags=flags).astype(np.float32)
    seen = cv2.warpPerspective(np.ones(photo_u.shape[:2], np.uint8), to_photo, size, flags=flags) > 0
    k = max(3, round(_INK_MM * q) | 1)
    closed = cv2.morphologyEx(rect, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    closed = cv2.GaussianBlur(closed, (0, 0), 1.0)  # a photo's noise, over half a millimetre
    art = board_image(board, q) > 127
    o = round(m * q)  # the board's corner in the rectified photo: `o` px in from each side
    square = max(1, round(board.square_mm * q))
    step = max(1, round(_STEP_MM * q))
    first, least, gone = (max(1, round(v * q)) for v in (_FIRST_MM, _LEAST_MM, _GONE_MM))
    ds = np.arange(first, o, step)
    out = []
    # Each side read alike, turned to the top (np.rot90 turns counterclockwise): its board's first
    # square of rows, and the lines above it, d px out, row o - d.
    for turns in (-1, 0, 1, 2):  # left, top, right, bottom
        rect_t, closed_t = np.rot90(rect, turns), np.rot90(closed, turns)
        seen_t, art_t = np.rot90(seen, turns), np.rot90(art, turns)
        near = rect_t[o : o + square, o : o + art_t.shape[1]]
        sel = art_t[:square] & seen_t[o : o + square, o : o + art_t.shape[1]]
        if sel.sum() < 20:
            out.append(0.0)
            continue
        # The white's light: its lighter half (the white round a ChArUco square's marker is a few
        # mm, and its pixels next to the black are blurred darker).
        whites = near[sel]
        norms = np.linalg.norm(whites, axis=1)
        level = np.median(whites[norms >= np.median(norms)], axis=0)
        light = float(np.linalg.norm(level))
        lines = closed_t[o - ds, o : o + art_t.shape[1]].transpose(1, 0, 2)
        ok = seen_t[o - ds, o : o + art_t.shape[1]].T
        # lines: (position along the side, distance out, 3); each position's paper ends where
        # `gone` of it in a row is seen and is not paper
        paper = _paper(lines, ok, level, max(1, round(_LAG_MM * q / step)))
        run = max(1, gone // step)
        # (out of the photo is no end: the photo's edge near a side would read as the sheet's)
        window = np.asarray(np.lib.stride_tricks.sliding_window_view(
            np.pad(~paper & ok, ((0, 0), (0, run - 1)), constant_values=False), run, axis=1).all(axis=2))
        ends = np.where(window.any(axis=1), window.argmax(axis=1), len(ds))
        ends[~paper[:, 0]] = 0
        # positions whose paper starts at the board: the others are hidden by the part (or its
        # shadow) or show no paper; a side shows paper if enough do
        starts = ends > 0
        if starts.sum() < _STARTS * max(1, int(ok[:, 0].sum())):
            out.append(0.0)
            continue
        # The paper's edge is straight: most positions end at it. A part on the margin or its
        # shadow ends some early, a table alike the paper some later (or never, within the
        # window: those count only as most of the side); the commonest end, to a millimetre.
        counts = np.bincount(ends[starts], minlength=len(ds) + 1).astype(np.float64)
        if counts[-1] >= _NO_END * starts.sum():
            # most of the side's "paper" does not end within MAX_MARGIN_MM: where it mostly runs
            # out of the photo, paper reaches the photo's edge (the sheet's near side, cut by the
            # frame); where it goes on in view, a light table, or a sheet larger than that, is
            # modelled as the table, as before the sheet was read
            never = starts & (ends == len(ds))
            leaves = never & ~ok.all(axis=1)
            out.append(MAX_MARGIN_MM if leaves.sum() >= _LEAVES * never.sum() else 0.0)
            continue
        counts[-1] = 0
        per_mm = np.convolve(counts, np.ones(max(1, round(1.0 / _STEP_MM))), mode="same")
        margin = int(ds[np.clip(int(np.argmax(per_mm)) - 1, 0, len(ds) - 1)])
        # and the paper's edge is a step in colour: a faint stripe of a light table is not one
        k_end = min(int(np.argmax(per_mm)), len(ds) - 1)
        w = max(1, round(_GONE_MM / _STEP_MM))
        # (across the end where it was seen: the positions ending there, not those a part hides)
        voters = starts & (np.abs(ends - k_end) <= run)
        inside = np.median(lines[voters][:, max(0, k_end - w) : k_end].reshape(-1, 3), axis=0)
        beyond = lines[voters][:, k_end + 1 : k_end + 1 + w].reshape(-1, 3)
        if len(beyond) == 0 or np.linalg.norm(inside - np.median(beyond, axis=0)) < _EDGE_STEP * light:
            out.append(0.0)
            continue
        out.append(margin / q if margin >= least else 0.0)
    left, top, right, bottom = out
    return left, top, right, bottom


def ink_strokes(photo_u: np.ndarray, paper: np.ndarray, stroke_px: float) -> np.ndarray:
    """The print on the paper: pixels of `photo_u` (H, W, 3) within `paper` (H, W) bool darker than
    the paper round them by a stroke under `stroke_px` wide (a grey closing's black-hat), dilated
    by a pixel for their blurred edge: (H, W) bool. A part is wider than that everywhere (its
    outline is convex), so none of it is ink."""
    grey = cv2.cvtColor(photo_u, cv2.COLOR_RGB2GRAY)
    k = max(3, round(stroke_px) | 1)
    hat = cv2.morphologyEx(grey, cv2.MORPH_BLACKHAT, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    closed = cv2.morphologyEx(grey, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    ink = (hat.astype(np.float32) > 0.15 * np.maximum(closed.astype(np.float32), 1.0)) & paper
    return cast("np.ndarray", cv2.dilate(ink.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)

"""The printed sheet round a hand-held board: its margins read from the photo against the layout
the renderer printed (`prismpbr` lays the board on a page with a margin, a ruler and a text line,
as `prism board` prints it), and its print told from a part."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from prismcore.errors import InputError
from prismcore.station.board import board_image, default_board
from prismcore.station.calibrate import board_pose
from prismcore.station.handheld import _board_view, board_camera
from prismcore.station.sheet import MAX_MARGIN_MM, ink_strokes, sheet_margins
from prismcore.station.undistort import undistorter
from prismpbr import DEVELOPMENT, handheld_scene, render_scene

# Small fast renders on the tables whose colour is not the paper's (a grey metal or laminate
# table as light as the paper reads as paper, up to MAX_MARGIN_MM: said in sheet_margins).
SMALL = replace(DEVELOPMENT, name="test", image_size=(1024, 768), spp=4, tables=(1, 0, 0, 1, 1))


@pytest.fixture(scope="module")
def sheets(tmp_path_factory):
    import os

    os.environ["PRISM_PBR_CACHE"] = str(tmp_path_factory.mktemp("pbr"))
    out = []
    try:
        for seed in (910, 911, 912, 913):
            sc = handheld_scene(seed, SMALL)
            photo = render_scene(sc)
            bw, bh = sc.board.size_mm
            (pw, ph), (ox, oy) = sc.paper_mm, sc.page_board_offset_mm
            true = (ox, oy, pw - bw - ox, ph - bh - oy)
            try:  # (the renderer's noise differs run to run: a board may be refused, once in a while)
                view = _board_view(photo, sc.board)
                cam = board_camera(photo, sc.board, view)
            except InputError:
                out.append((seed, true, (0.0, 0.0, 0.0, 0.0)))
                continue
            pose = board_pose(view, cam)
            R, t = pose.rotation(), pose.translation()
            pose_h = cam.matrix() @ np.column_stack([R[:, 0], R[:, 1], t])
            out.append((seed, true, sheet_margins(undistorter(cam).image(photo), sc.board, pose_h)))
    finally:
        del os.environ["PRISM_PBR_CACHE"]
    return out


def test_a_margin_is_read_within_2_mm_or_left_out(sheets) -> None:
    """Sides' margins are the printed ones within 2 mm, or 0 (one wrong at most). A side read 0
    (hidden by the part or its shadow, out of view, a table as light and grey as the paper, or a
    paper edge that is no clear step in colour) has its paper modelled as table, as before the
    sheet was read. The count read is what the engine holds on these small, noisy renders today
    (9 of 16), with room for their noise, to keep; the figures that count are
    benchmarks/station_sets.py's."""
    read, wrong = 0, []
    for seed, true, got in sheets:
        for side, t, g in zip(("left", "top", "right", "bottom"), true, got, strict=True):
            if abs(g - min(t, MAX_MARGIN_MM)) <= 2.0:
                read += 1
            elif g != 0:
                wrong.append((seed, side, t, g))
    assert read >= 7, sheets
    assert len(wrong) <= 1, wrong


def test_the_print_on_the_paper_is_ink_and_a_part_is_not() -> None:
    """A ruler, its ticks and a text line drawn on white paper are ink; a dark part's block is
    not, nor the paper round it."""
    photo = np.full((300, 400, 3), 200, np.uint8)
    cv2.line(photo, (20, 40), (220, 40), (30, 30, 30), 1)
    for x in range(20, 221, 20):
        cv2.line(photo, (x, 40), (x, 30), (30, 30, 30), 1)
    cv2.putText(photo, "100 mm check ruler", (20, 60), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (30, 30, 30), 1,
                cv2.LINE_AA)
    photo[120:260, 200:360] = (60, 50, 40)  # the part
    paper = np.ones(photo.shape[:2], bool)
    ink = ink_strokes(photo, paper, stroke_px=4.0)
    assert ink[40, 20:221].mean() > 0.9
    assert ink[30:40, 100].any()
    text = photo[45:62, 20:160].min(axis=2) < 100
    assert ink[45:62, 20:160][text].mean() > 0.9
    assert not ink[125:255, 205:355].any()
    assert ink[100:, :].mean() < 0.02


@pytest.mark.parametrize("fall", [0.0, 0.15, 0.3])
@pytest.mark.parametrize("side", ["left", "top", "right", "bottom"])
def test_a_margin_in_soft_shadow_is_read_to_the_sheets_edge(side: str, fall: float) -> None:
    """A sheet lit from one side (an area light, a window, the part's own soft shadow) darkens
    smoothly away from the board, here by `fall` of its light across the margin, to 30 % below
    the white squares: the margins are still read to the sheet's edge, a step to the table.
    (Read against the white squares' light alone, a margin 12 % darker than they ended there.)"""
    board = default_board("A4")
    q = 3.0  # px per mm of the drawn photo: the board's plane seen square on
    margins = {"left": 30.0, "top": 20.0, "right": 25.0, "bottom": 40.0}
    bw, bh = board.size_mm
    pad = 70.0
    size = (round((bw + 2 * pad) * q), round((bh + 2 * pad) * q))
    photo = np.empty((size[1], size[0], 3), np.float32)
    photo[:] = (95, 70, 60)  # a brown table
    x0, y0 = round((pad - margins["left"]) * q), round((pad - margins["top"]) * q)
    x1, y1 = round((pad + bw + margins["right"]) * q), round((pad + bh + margins["bottom"]) * q)
    photo[y0:y1, x0:x1] = 235.0
    art = board_image(board, q).astype(np.float32)
    bx, by = round(pad * q), round(pad * q)
    photo[by:by + art.shape[0], bx:bx + art.shape[1]] = (art * (235 / 255))[..., None]
    # the light falls off past the board's edge on `side`, smoothly, to `fall` at the sheet's edge
    yy, xx = np.mgrid[0:size[1], 0:size[0]].astype(np.float32)
    out = {"left": bx - xx, "top": by - yy, "right": xx - (bx + art.shape[1]),
           "bottom": yy - (by + art.shape[0])}[side]
    photo *= (1 - fall * np.clip(out / (margins[side] * q), 0, 1))[..., None]
    rng = np.random.default_rng(3)
    photo = np.clip(photo + rng.normal(0, 4, photo.shape), 0, 255).astype(np.uint8)
    pose_h = np.array([[q, 0, bx - 0.5], [0, q, by - 0.5], [0, 0, 1.0]])
    got = dict(zip(("left", "top", "right", "bottom"), sheet_margins(photo, board, pose_h), strict=True))
    assert all(abs(got[k] - margins[k]) <= 1.0 for k in margins), got

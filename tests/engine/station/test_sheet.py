"""The printed sheet round a hand-held board: its margins read from the photo against the layout
the renderer printed (`prismpbr` lays the board on a page with a margin, a ruler and a text line,
as `prism board` prints it), and its print told from a part."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from prismcore.errors import InputError
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

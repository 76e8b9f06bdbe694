"""Hand-held on physically based scenes it was never tuned to (`prismpbr`: the board printed on a
sheet with its margin, ruler and text on a real table, area lights and a window, clutter, auto
exposure and white balance; kraft, glossy print, aluminium, steel, black and white plastic).
Small, fast scenes (parts of 30-120 mm; found is counted where the board shows round the part):
the bounds are what the engine holds on them today, to keep; the figures that count are
benchmarks/station_sets.py's report sets."""

from __future__ import annotations

from dataclasses import replace

import pytest

from prismcore.errors import InputError, PartRefusedError
from prismcore.station.handheld import measure_on_board
from prismpbr import DEVELOPMENT, board_corners_shown, handheld_scene, render_scene

SMALL = replace(DEVELOPMENT, name="test", image_size=(800, 600), spp=4, hand_part_mm=(30.0, 120.0))
SEEDS = range(930, 946)


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    import os

    before = os.environ.get("PRISM_PBR_CACHE")
    os.environ["PRISM_PBR_CACHE"] = str(tmp_path_factory.mktemp("pbr"))
    out = []
    try:
        for seed in SEEDS:
            sc = handheld_scene(seed, SMALL)
            assert sc.part is not None
            photo = render_scene(sc)
            try:
                outcome = measure_on_board(photo, sc.board)
            except InputError as exc:
                outcome = exc
            out.append((sc, board_corners_shown(sc), outcome))
    finally:
        if before is None:
            del os.environ["PRISM_PBR_CACHE"]
        else:
            os.environ["PRISM_PBR_CACHE"] = before
    return out


def test_parts_on_a_board_that_shows_are_found_and_a_refusal_says_why(outcomes) -> None:
    shown = [(sc, o) for sc, n, o in outcomes if n >= 12]
    found = [o for _, o in shown if not isinstance(o, InputError)]
    # today 6 of the 12 whose board shows (the engine before the sheet's edge, the table's zone and
    # texture and stray corners were mended: 3); Mitsuba's noise differs run to run
    assert len(shown) >= 10 and len(found) >= 0.33 * len(shown), [
        str(o)[:60] for _, o in shown if isinstance(o, InputError)]
    for _, _, o in outcomes:
        if isinstance(o, InputError):
            said = str(o)
            assert (said[0].islower() or said[0].isdigit()) and ": " in said  # a sentence: what to change
        if isinstance(o, PartRefusedError):
            assert o.photo is not None  # the evidence to show what was taken


def test_no_dimension_is_far_off_unsaid(outcomes) -> None:
    """The oracle is the render's truth: a dimension over 5 % off carries a warning (the focal
    length found from the board is said on every photo, and is no such warning)."""
    for sc, _, m in outcomes:
        if isinstance(m, InputError):
            continue
        warned = [w for w in m.warnings if "found from the board" not in w]
        for key, true in sc.part.dimensions.items():
            if abs(m.dimensions[key] - true) > 0.05 * true:
                assert warned, (sc.seed, key, m.dimensions[key], true)

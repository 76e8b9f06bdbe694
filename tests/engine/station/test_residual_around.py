"""The segmentation's residual computed only round the part gives every pixel it computes the
value the whole window's residual gives it (the oracle: `_residual` over the whole window)."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from prismcore.station.segment import _INSIDE, _STRIP, _residual


@pytest.mark.parametrize("seed", range(6))
def test_the_residual_round_the_part_is_the_whole_windows_where_computed(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(40, 260, 2))
    bg = rng.uniform(0, 255, (h, w, 3)).astype(np.float32)
    P = bg * rng.uniform(0.5, 1.1, (h, w, 1)).astype(np.float32)  # a shadow, say
    core = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(core, np.array([[w * 0.2, h * 0.1], [w * 0.9, h * 0.3], [w * 0.7, h * 0.95],
                                       [w * 0.1, h * 0.8]], np.int32), 1)
    P[core > 0] = rng.uniform(0, 255, 3).astype(np.float32)  # the part
    whole = _residual(P, bg)
    around = _residual(P, bg, core > 0)
    computed = around != _INSIDE
    np.testing.assert_array_equal(around[computed], whole[computed])
    # what was left out is inside the core, whole strips' runs of it
    assert not (~computed & (core == 0)).any()
    if h >= 2 * _STRIP and w >= 100:
        assert (~computed).sum() > 0.2 * core.sum()


def test_without_a_core_every_pixel_is_computed() -> None:
    rng = np.random.default_rng(9)
    bg = rng.uniform(0, 255, (70, 90, 3)).astype(np.float32)
    P = rng.uniform(0, 255, (70, 90, 3)).astype(np.float32)
    np.testing.assert_array_equal(_residual(P, bg, np.zeros((70, 90), bool)), _residual(P, bg))


def test_a_core_at_the_windows_edge_still_gives_the_whole_window() -> None:
    rng = np.random.default_rng(4)
    bg = rng.uniform(0, 255, (30, 200, 3)).astype(np.float32)  # one strip
    P = rng.uniform(0, 255, (30, 200, 3)).astype(np.float32)
    core = np.zeros((30, 200), bool)
    core[:, :120] = True  # the run inside reaches column 0: one block is left, from 120 on
    around = _residual(P, bg, core)
    assert around.shape == (30, 200)
    np.testing.assert_array_equal(around[:, 120:], _residual(P, bg)[:, 120:])
    assert (around[:, :120] == _INSIDE).all()


@pytest.mark.parametrize("seed", [3, 100, 204, 500, 501, 504, 704, 1303, 5024, 5032, 6003])
def test_the_outline_is_the_same_with_the_inside_skipped(seed: int, monkeypatch) -> None:
    """The oracle: segment_part with the residual over the whole window. Station scenes (large and
    small parts, a part near the table's colour) and hand-held ones (dark parts on the board's
    black squares, where the coarse blob is least like the part)."""
    import prismcore.station.measure as measure
    from prismcore.errors import InputError
    from prismcore.station import measure_on_station
    from prismcore.station.handheld import measure_on_board
    from prismcore.station.segment import segment_part
    from prismsynth.station import station_scene, station_setup

    from .conftest import station_for

    calls: list[tuple] = []
    monkeypatch.setattr(measure, "segment_part", lambda *a, **k: calls.append(a) or segment_part(*a, **k))
    try:
        if seed >= 5000:
            sc = station_scene(seed, station_setup(seed), nudge=False, inside_board=True, max_size_mm=80)
            measure_on_board(sc.photo, sc.setup.board)
        else:
            sc = station_scene(seed, station_setup(seed // 100))
            measure_on_station(sc.photo, station_for(sc))
    except InputError:
        pass  # refused after the segmentation, or by it: the outlines are compared all the same
    assert calls
    for args in calls:
        try:
            whole = segment_part(*args, skip_inside=False)
        except InputError as exc:
            with pytest.raises(InputError, match=re.escape(str(exc)[:40])):
                segment_part(*args)
            continue
        skipped = segment_part(*args)
        np.testing.assert_array_equal(skipped.contour, whole.contour)
        assert skipped.warnings == whole.warnings and skipped.contrast == whole.contrast

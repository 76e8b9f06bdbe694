"""A dark part on the board's squares: pixel by pixel the black squares, or the white ones in a
deep shadow, so only the pattern it breaks shows it (`prismcore.station.segment`)."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.station.board import board_image
from prismcore.station.segment import segment_part
from prismsynth.station import station_board


@pytest.mark.parametrize("grey", [45, 62])
@pytest.mark.parametrize("box", [(200, 230, 250, 290), (205, 240, 260, 285), (180, 215, 240, 275)])
def test_a_small_dark_part_on_the_squares_is_found_where_it_breaks_their_pattern(grey, box) -> None:
    """A small part as dark as the black print (45) or as a deep shadow of the white (62: a quarter
    of it) over a few squares: pixel by pixel it is the black squares, or the white ones shaded,
    so only the pattern it breaks shows it. It is found, roughly (under half its outline wrong),
    and said to be found so; it was refused as "no part found" where the coarse photo found it
    and the full-size one did not count the broken pattern."""
    pattern = board_image(station_board(), 1.5) > 127
    plate = np.full((480, 640, 3), 230.0, np.float32)
    h, w = pattern.shape
    plate[60 : 60 + h, 50 : 50 + w] = np.where(pattern[..., None], 230.0, 38.0)
    y0, y1, x0, x1 = box
    photo = plate.copy()
    photo[y0:y1, x0:x1] = grey
    rng = np.random.default_rng(1)

    def noisy(image: np.ndarray) -> np.ndarray:
        return np.clip(image + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)

    sil = segment_part(noisy(photo), noisy(plate), np.eye(3))
    truth = np.zeros(sil.mask.shape, bool)
    truth[y0:y1, x0:x1] = True
    assert (sil.mask & truth).sum() / (sil.mask | truth).sum() > 0.5
    assert sil.mirrored and any("breaks the support's pattern" in m for m in sil.warnings)


@pytest.mark.parametrize("length", [150, 400])
def test_a_cable_beside_the_part_is_left_out_and_said(length) -> None:
    """A thin dark line (a cable, a ruler's edge, a printed line) apart from the part is no second
    part: left out of the outline and of the blobs the caller sizes as parts, and said. (Long
    enough, it was refused as "2 parts found"; shorter, it went to the caller, which sized its
    bounding box on the support as a second part.)"""
    pattern = board_image(station_board(), 1.5) > 127
    plate = np.full((480, 640, 3), 230.0, np.float32)
    h, w = pattern.shape
    plate[60 : 60 + h, 50 : 50 + w] = np.where(pattern[..., None], 230.0, 38.0)
    photo = plate.copy()
    photo[200:270, 250:330] = (150, 110, 70)  # the part
    photo[440:456, 600 - length : 600] = (20, 20, 20)  # the cable, on the white below the board
    rng = np.random.default_rng(2)

    def noisy(image: np.ndarray) -> np.ndarray:
        return np.clip(image + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)

    sil = segment_part(noisy(photo), noisy(plate), np.eye(3))
    assert not sil.mask[430:466].any() and sil.mask[200:270, 250:330].mean() > 0.95
    assert sil.others == []
    assert any("thin thing(s) apart from the part left out" in m for m in sil.warnings)

"""A correct station's bias, on photos with their colour whole and halved.

The station verified with the sample's reference part (70 x 45 x 30 mm, placed 7 times as
`prism sample --station` places it) on 6 station setups (prismsynth seeds), once with the photos'
JPEG colour at full resolution (4:4:4, as a machine-vision camera saves) and once at half
resolution both ways (4:2:0, a phone's and most cameras' default). Either way the station is
unbiased within what 7 placements resolve: the bias's 95 % t interval holds the truth for 16 of
the 18 dimensions (a 95 % interval is expected to miss about 1).

Until the outline's step was read a second time from where the first reading put it
(`prismcore.station.edges.refine_outline`), the 4:2:0 photos read the part 0.03-0.20 mm long,
the height most, and the interval held the truth for 3 of 18: the threshold's outline lies further
out on them, and the part's and the support's levels, read 3-4 px either side of it, were read off
centre. (benchmarks/station_verification.py, with --chroma 444 and without: the same figures.)
"""

from __future__ import annotations

from datetime import UTC, datetime
from functools import cache

import numpy as np
import pytest

from prism_cli.sample_command import reference_placements
from prismcore.camera import CameraModel
from prismcore.station import Station, calibrate_station
from prismcore.station.board import default_board
from prismcore.station.certify import verify_station
from prismcore.station.verify import DIMENSIONS, Verification
from prismsynth.station import station_scene, station_setup

SEEDS = (1, 2, 3, 4, 5, 6)
REFERENCE = (70.0, 45.0, 30.0)
DATE = datetime(2026, 1, 2, tzinfo=UTC)


@cache
def _verification(seed: int, chroma: str) -> Verification:
    setup = station_setup(seed, board=default_board())
    K, (w, h) = setup.K, setup.image_size
    camera = CameraModel(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], dist=[float(v) for v in setup.dist],
                         image_width=w, image_height=h)
    plate = station_scene(seed, setup, parts=0, chroma=chroma).plate
    station: Station = calibrate_station(default_board(), plate, camera=camera, plate=plate)
    photos = [(f"reference-{i}", station_scene(1000 * seed + i, setup, box=box, chroma=chroma).photo)
              for i, box in enumerate(reference_placements(setup), 1)]
    return verify_station(station, photos, REFERENCE, 2.0, DATE)


@pytest.mark.parametrize("chroma", ["444", "420"])
def test_the_bias_interval_holds_the_truth(chroma):
    held, biases = 0, []
    for seed in SEEDS:
        done = _verification(seed, chroma)
        assert done.verified, (seed, done.decided_by)
        for name in DIMENSIONS:
            low, high = done.dimensions[name].bias_ci95_mm
            held += low <= 0.0 <= high
            biases.append(done.dimensions[name].bias_mm)
    # 16 of 18 both ways here; a 95 % interval holding the truth is not expected to hold it every time
    assert held >= 15, held
    assert max(np.abs(biases)) < 0.08, biases


@pytest.mark.parametrize("seed", SEEDS[:3])
def test_halving_the_colour_moves_no_bias_beyond_chance(seed):
    # the two biases, each a mean of 7 placements, differ by under 3 standard errors of their
    # difference (before the second reading the height moved by +0.12 to +0.14 mm, over 5)
    whole, halved = _verification(seed, "444"), _verification(seed, "420")
    for k in DIMENSIONS:
        a, b = whole.dimensions[k], halved.dimensions[k]
        moved = b.bias_mm - a.bias_mm
        se = float(np.hypot(a.repeatability_mm, b.repeatability_mm)) / np.sqrt(len(a.errors_mm))
        assert abs(moved) <= 3 * se, (k, moved, se)

"""A correct station's bias, on photos with their colour whole and halved.

The station verified with the sample's reference part (70 x 45 x 30 mm, placed 7 times as
`prism sample --station` places it) on 6 station setups (prismsynth seeds). With the photos'
colour at full resolution (JPEG 4:4:4, as a machine-vision camera saves, or PNG) the station is
unbiased within what 7 placements resolve: the bias's 95 % t interval holds the truth for 16 of
the 18 dimensions (a 95 % interval is expected to miss about 1). With the colour at half
resolution both ways (JPEG 4:2:0, a phone's and most cameras' default) the same scenes read
+0.03 to +0.20 mm long, the height most, and the interval holds the truth for 3 of 18: the part's
outline is read 0.1-0.2 px outward along its near-horizontal sides (against its true silhouette;
along the near-vertical ones within 0.05 px), and only the part's photo's sampling matters (the
plate's does not). Why the halved colour moves those sides and not the others was not taken
further. The verification is right to call that bias significant; under 10 % of 2T, the rule
accepts it.
(benchmarks/station_verification.py --chroma 444 and without it: the same figures.)
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


def test_on_full_colour_photos_the_bias_interval_holds_the_truth():
    held, biases = 0, []
    for seed in SEEDS:
        done = _verification(seed, "444")
        assert done.verified, (seed, done.decided_by)
        for name in DIMENSIONS:
            low, high = done.dimensions[name].bias_ci95_mm
            held += low <= 0.0 <= high
            biases.append(done.dimensions[name].bias_mm)
    # 16 of 18 here; a 95 % interval holding the truth is not expected to hold it every time
    assert held >= 15, held
    assert max(np.abs(biases)) < 0.08, biases


@pytest.mark.parametrize("seed", SEEDS[:3])
def test_photos_with_half_resolution_colour_read_the_part_long(seed):
    whole, halved = _verification(seed, "444"), _verification(seed, "420")
    assert halved.verified, halved.decided_by  # a bias under 10 % of 2T
    longer = {k: halved.dimensions[k].bias_mm - whole.dimensions[k].bias_mm for k in DIMENSIONS}
    assert 0.05 <= longer["height"] <= 0.3, longer
    assert all(-0.05 <= v <= 0.2 for v in longer.values()), longer
    low, high = halved.dimensions["height"].bias_ci95_mm
    assert low > 0, (low, high)  # significant: the verification says so

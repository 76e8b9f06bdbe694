"""The station on physically based scenes it was never tuned to (`prismpbr`: path traced, area
lights and a window, soft coloured shadows, auto exposure and white balance, rounded edges; kraft,
glossy print, black and white plastic). Small, fast scenes: the bounds are what the engine holds on
them today, to keep; the figures that count are benchmarks/station.py --sets' report sets."""

from __future__ import annotations

from dataclasses import replace

import pytest

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.station import calibrate_station, measure_on_station
from prismpbr import DEVELOPMENT, render_scene, station_scenes

SMALL = replace(DEVELOPMENT, name="test", image_size=(800, 600), spp=4, materials=(1, 1, 0, 0, 1, 1))


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    import os

    os.environ["PRISM_PBR_CACHE"] = str(tmp_path_factory.mktemp("pbr"))
    out = []
    for seed in (901, 902):
        plate, photos = station_scenes(seed, 4, SMALL)
        cam = plate.camera
        camera = CameraModel(fx=cam.K[0, 0], fy=cam.K[1, 1], cx=cam.K[0, 2], cy=cam.K[1, 2],
                             dist=[float(v) for v in cam.dist], image_width=cam.size[0],
                             image_height=cam.size[1])
        empty = render_scene(plate)
        station = calibrate_station(plate.board, empty, camera=camera, plate=empty)
        for sc in photos:
            assert sc.part is not None
            try:
                out.append((sc.part, measure_on_station(render_scene(sc), station)))
            except InputError as exc:
                out.append((sc.part, str(exc)))
    del os.environ["PRISM_PBR_CACHE"]
    return out


def test_most_parts_are_found_and_a_refusal_says_why(outcomes) -> None:
    found = [m for _, m in outcomes if not isinstance(m, str)]
    assert len(found) >= 6, [m for _, m in outcomes if isinstance(m, str)]
    for _, m in outcomes:
        if isinstance(m, str):
            assert m and m[0].islower()  # a sentence, not a traceback


def test_no_dimension_is_far_off_unsaid(outcomes) -> None:
    """The oracle is the render's truth: a dimension over 5 % off carries a warning."""
    for part, m in outcomes:
        if isinstance(m, str):
            continue
        for key, true in part.dimensions.items():
            if abs(m.dimensions[key] - true) > 0.05 * true:
                assert m.warnings, (part, key, m.dimensions[key])


def test_the_stated_sigma_covers_most_errors(outcomes) -> None:
    errors = [(abs(m.dimensions[k] - t), m.uncertainty[k]) for part, m in outcomes if not isinstance(m, str)
              for k, t in part.dimensions.items()]
    within = sum(e <= 3 * s for e, s in errors) / len(errors)
    # 48-57 % at this size today (Mitsuba's noise differs run to run); the report sets: station.py --sets
    assert within >= 0.4, within

"""A station's verification and drift on renders, over many stations (prismsynth setups).

For each seed: a station calibrated with its true camera on its plane photo; the sample's reference
part (70 x 45 x 30 mm) placed 7 times across the board (`prism sample --station`'s placements);
verified as `prism station verify` does (`verify_measured`) at +-T on the correct station, on
stations whose scale is 1 % off (the board described 1 % larger or smaller than printed: every
length, the plane's distance among them, 1 % off) and on one whose focal length is 1 % off (given
at calibration, the plane's pose fitted with it); then a photo after the camera turned by 5, 10
and 20 px, measured with `scan.certify`. The photos are JPEGs of quality 85 with the colour at
half resolution (4:2:0) unless --chroma 444.

    .venv/bin/python benchmarks/station_verification.py --seeds 1-12 --tolerance 2
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from prismcore import InputError
from prismcore.camera import CameraModel
from prismcore.station.board import BoardSpec, default_board
from prismcore.station.calibrate import Station, calibrate_station
from prismcore.station.certify import MOVED_PX, verify_measured
from prismcore.station.measure import measure_on_station
from prismcore.station.scan import certify
from prismcore.station.verify import DIMENSIONS, Verification
from prismsynth.station import StationSetup, station_scene, station_setup

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))
from cli.sample_command import REFERENCE_MM, reference_placements

MOVES_PX = (5.0, 10.0, 20.0)


def camera_of(setup: StationSetup, focal_factor: float = 1.0) -> CameraModel:
    K = setup.K
    w, h = setup.image_size
    return CameraModel(fx=K[0, 0] * focal_factor, fy=K[1, 1] * focal_factor, cx=K[0, 2], cy=K[1, 2],
                       dist=[float(v) for v in setup.dist], image_width=w, image_height=h)


def scaled(board: BoardSpec, factor: float) -> BoardSpec:
    """The board described `factor` times its printed size (a printer's scaling gone unnoticed)."""
    return board.model_copy(update={"square_mm": board.square_mm * factor,
                                    "marker_mm": board.marker_mm * factor})


def stations(seed: int, chroma: str = "420") -> tuple[StationSetup, dict[str, Station]]:
    """The setup and its stations: correct, scale 1 % high and low, focal length 1 % high."""
    board = default_board()
    setup = station_setup(seed, board=board)
    plate = station_scene(seed, setup, parts=0, chroma=chroma).plate
    cam = camera_of(setup)
    return setup, {
        "correct": calibrate_station(board, plate, camera=cam, plate=plate),
        "scale +1 %": calibrate_station(scaled(board, 1.01), plate, camera=cam, plate=plate),
        "scale -1 %": calibrate_station(scaled(board, 0.99), plate, camera=cam, plate=plate),
        "focal +1 %": calibrate_station(board, plate, camera=camera_of(setup, 1.01), plate=plate),
    }


def placements(seed: int, setup: StationSetup, chroma: str = "420") -> list[np.ndarray]:
    photos = []
    for i, box in enumerate(reference_placements(setup), 1):
        try:
            photos.append(station_scene(1000 * seed + i, setup, box=box, chroma=chroma).photo)
        except ValueError:  # that placement is out of this camera's view
            continue
    return photos


STILL_SHIFTS: list[float] = []  # the correct stations' placements: the camera nudged 0-3 px


def verification(station: Station, photos: list[np.ndarray], tolerance: float,
                 still: bool = False) -> Verification | str:
    measured = []
    for i, photo in enumerate(photos):
        try:
            m = measure_on_station(photo, station)
        except InputError as exc:
            return f"refused: {exc}"
        if still:
            STILL_SHIFTS.append(m.registration.shift_px)
        measured.append((str(i), m))
    try:
        return verify_measured(station, measured, REFERENCE_MM, tolerance,
                               datetime(2026, 1, 1, tzinfo=UTC))
    except InputError as exc:
        return f"refused: {exc}"


def moved_setup(setup: StationSetup, shift_px: float, seed: int) -> StationSetup:
    """The camera turned so the image moves by about `shift_px` (about an axis across the view)."""
    rng = np.random.default_rng([seed, int(shift_px)])
    axis = np.array([*rng.normal(size=2), 0.0])
    axis *= shift_px / setup.K[0, 0] / np.linalg.norm(axis)
    dR = cv2.Rodrigues(axis)[0]
    return replace(setup, R=dR @ setup.R, t=dR @ setup.t)


def moved_photo(seed: int, setup: StationSetup, shift_px: float, chroma: str = "420") -> np.ndarray:
    box = reference_placements(setup)[2]  # the board's centre
    return station_scene(7000 + seed, moved_setup(setup, shift_px, seed), box=box, nudge=False,
                         chroma=chroma).photo


def seed_list(text: str) -> list[int]:
    """Seeds as "A-B" (both ends) or "A,B,C"."""
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(v) for v in text.split(",")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--tolerance", type=float, default=2.0)
    parser.add_argument("--chroma", choices=("420", "444"), default="420",
                        help="the JPEGs' colour sampling: 420 halves the colour's resolution (phones, "
                             "most cameras), 444 keeps it whole (a machine-vision camera's setting)")
    args = parser.parse_args()
    verdicts: dict[str, list[bool]] = {}
    covered = []
    flagged = []
    for seed in seed_list(args.seeds):
        setup, kinds = stations(seed, args.chroma)
        photos = placements(seed, setup, args.chroma)
        for name, station in kinds.items():
            done = verification(station, photos, args.tolerance, still=name == "correct")
            if isinstance(done, str):
                print(f"seed {seed:3d} {name:<11} {done}")
                verdicts.setdefault(name, []).append(False)
                continue
            verdicts.setdefault(name, []).append(done.verified)
            bias = " ".join(f"{done.dimensions[k].bias_mm:+.3f}" for k in DIMENSIONS)
            ci = [done.dimensions[k].bias_ci95_mm for k in DIMENSIONS]
            if name == "correct":
                covered.append(sum(lo <= 0 <= hi for lo, hi in ci))
            print(f"seed {seed:3d} {name:<11} {len(photos)} placements  bias w/d/h {bias} mm  "
                  f"{'verified' if done.verified else 'NOT verified'}")
        correct = kinds["correct"]
        for shift in MOVES_PX:
            try:
                m = measure_on_station(moved_photo(seed, setup, shift, args.chroma), correct)
            except InputError as exc:
                print(f"seed {seed:3d} moved {shift:4.0f} px: refused ({exc})")
                flagged.append(True)  # refused is flagged too: nothing measured unsaid
                continue
            c = certify(m, correct, args.tolerance)
            d = c["drift"]
            flagged.append(bool(d["moved"]))
            print(f"seed {seed:3d} moved {shift:4.0f} px: shift {d['shift_px']:5.2f} px "
                  f"{d['shift_mm']:5.2f} mm, moved {d['moved']}, cost w {d['cost_mm']['width']:.3f} mm, "
                  f"reverify {d['reverify']}")
    print()
    for name, v in verdicts.items():
        print(f"{name:<11} verified {sum(v)} of {len(v)} stations (+-{args.tolerance:g} mm)")
    print(f"correct stations: the bias's 95 % interval holds 0 for {sum(covered)} of {3 * len(covered)} "
          "dimensions")
    print(f"camera moved 5-20 px: flagged {sum(flagged)} of {len(flagged)} photos")
    moved = sum(s > MOVED_PX for s in STILL_SHIFTS)
    print(f"camera still (nudged 0-3 px): flagged {moved} of {len(STILL_SHIFTS)} photos, shift at most "
          f"{max(STILL_SHIFTS, default=0):.2f} px")


if __name__ == "__main__":
    main()

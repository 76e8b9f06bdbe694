"""Render (into the cache, outside the repository) the physically based scene sets that
benchmarks/station.py --sets measures: N stations of P parts and H hand-held photos of a set.

    .venv/bin/python benchmarks/pbr_render.py --set development|report [--stations 10] [--parts 10]
        [--hand-held 60]
"""

from __future__ import annotations

import argparse
import time

from prismpbr import SETS, handheld_scene, render_scene, station_scenes
from prismpbr.sets import handheld_seeds, station_seeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", choices=sorted(SETS), required=True)
    parser.add_argument("--stations", type=int, default=10)
    parser.add_argument("--parts", type=int, default=10)
    parser.add_argument("--hand-held", type=int, default=60)
    args = parser.parse_args()
    settings = SETS[args.set]
    started = time.time()
    n = 0
    for s in station_seeds(settings, args.stations):
        plate, photos = station_scenes(s, args.parts, settings)
        for scene in [plate, *photos]:
            render_scene(scene)
            n += 1
        print(f"station {s}: {n} renders, {time.time() - started:.0f} s", flush=True)
    for seed in handheld_seeds(settings, args.hand_held):
        render_scene(handheld_scene(seed, settings))
        n += 1
    print(f"{n} renders in {time.time() - started:.0f} s")


if __name__ == "__main__":
    main()

"""`prism sample`: render a synthetic photo of a box of known size, with its job spec; or, with
`--station`, a whole example station (its calibration photos, parts and a reference part)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prismcore.errors import InputError

if TYPE_CHECKING:
    from prismsynth.station import StationBox, StationSetup

__all__ = ["REFERENCE_MM", "sample"]

# The example station: its camera and board (prism board's default, A4), the renderer's seeds.
_STATION_SEED = 11
_CALIBRATION_VIEWS = 8
_PART_SEEDS = (21, 22, 23, 24, 25, 26)
_HELD_SEED = 5002
_MOVED_SEED = 5003
MOVED_PX = 10.0  # moved.jpg: the reference part after the camera was knocked, turned this far in the photo
# The reference part (a box measured with calipers): width >= depth, height, mm, as the station
# reports them; placed 7 times across the board, turned so two of its sides face the camera.
REFERENCE_MM = (70.0, 45.0, 30.0)
_PLACES = (
    (0.25, 0.3, 25),
    (0.75, 0.3, 115),
    (0.5, 0.5, 45),
    (0.25, 0.72, 135),
    (0.75, 0.72, 65),
    (0.5, 0.15, 155),
    (0.5, 0.85, 35),
)  # board fractions x, y; yaw from the azimuth of the camera's sight line to the placement


def sample(
    out: Annotated[Path | None, typer.Option(help="Folder for box.jpg and job.json.")] = None,
    width_mm: Annotated[float, typer.Option(help="Box width.")] = 120.0,
    height_mm: Annotated[float, typer.Option(help="Box height.")] = 80.0,
    depth_mm: Annotated[float, typer.Option(help="Box depth.")] = 60.0,
    seed: Annotated[int, typer.Option(help="Scene seed.")] = 1,
    station: Annotated[
        Path | None,
        typer.Option(
            help="Instead of --out: a folder for an example station, rendered: board.json, plane.jpg, "
            "empty.jpg, calib/ (the board in 8 poses), parts/ (6 parts, their true sizes in "
            "true_sizes.csv), reference/ (one reference part placed 7 times, for prism station "
            "verify), moved.jpg (the reference after the camera turned 10 px) and handheld.jpg."
        ),
    ] = None,
) -> None:
    """Render an oblique photo of a box and write a spec that measures it (--out); or render an
    example station's photos (--station), so the station's commands can be tried with no camera."""
    if (out is None) == (station is None):
        raise InputError(
            "give --out FOLDER (a box's photo and its spec) or --station FOLDER (a station's photos)"
        )
    if station is not None:
        _station_sample(station)
        return
    assert out is not None
    from prismcore.bounds import LENGTH_MM_RANGE
    from prismsynth import Box, render_oblique_view, save_image

    low, high = LENGTH_MM_RANGE
    for flag, value in (("--width-mm", width_mm), ("--height-mm", height_mm), ("--depth-mm", depth_mm)):
        if not low <= value <= high:  # the spec written would be refused (prismcore.bounds)
            raise InputError(f"{flag} {value:g}: a length is {low:g} to {high:g} mm")
    box = Box(width_mm, height_mm, depth_mm)
    scene = render_oblique_view(box, seed=seed)
    out.mkdir(parents=True, exist_ok=True)
    save_image(scene, out / "box.jpg")
    names = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
    spec = {
        "image": "box.jpg",
        "points": {n: [round(c) for c in scene.points[n]] for n in names},  # clicks are whole px
        "focal_px": scene.focal_px,
        "scale": {"kind": "pinhole", "distance_mm": round(scene.distance_mm, 3)},
    }
    (out / "job.json").write_text(json.dumps(spec, indent=2) + "\n")
    from rich.console import Console

    Console().print(
        f"true size {width_mm:g} x {height_mm:g} x {depth_mm:g} mm\n"
        f" image: {out / 'box.jpg'}\n  spec: {out / 'job.json'}"
    )


def reference_placements(setup: StationSetup) -> list[StationBox]:
    """The reference part's placements on the sample's board: spread over it, each turned 25-65
    degrees off the camera's line of sight to where it stands (two sides seen, as a user is told
    to place it)."""
    import numpy as np

    from prismsynth.station import StationBox

    camera = -setup.R.T @ setup.t  # the camera in the board's frame
    bw, bh = setup.board.size_mm
    width, depth, height = REFERENCE_MM
    boxes = []
    for fx, fy, yaw in _PLACES:
        x, y = fx * bw, fy * bh
        # the sight line to this placement, not to the board's centre: near a board's edge the two
        # part by 10-20 degrees, and a part turned 25 degrees off the one showed one side only
        azimuth = float(np.degrees(np.arctan2(camera[1] - y, camera[0] - x)))
        boxes.append(StationBox(width, depth, height, x, y, (azimuth + yaw) % 180, (205.0, 70.0, 45.0)))
    return boxes


def turned(setup: StationSetup, shift_px: float) -> StationSetup:
    """The setup's camera turned (about its own horizontal axis) so the photo moves by about
    `shift_px`: a knock the station's plate does not know of."""
    from dataclasses import replace

    import cv2
    import numpy as np

    dR = cv2.Rodrigues(np.array([shift_px / setup.K[1, 1], 0.0, 0.0]))[0]
    return replace(setup, R=dR @ setup.R, t=dR @ setup.t)


def _station_sample(folder: Path) -> None:
    """Render the example station into `folder` and say what is where."""
    import cv2
    import numpy as np

    from prismcore.station import default_board
    from prismsynth.station import calibration_views, station_scene, station_setup

    def save(name: str, rgb: np.ndarray) -> None:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(
            str(folder / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95]
        ):
            raise OSError(f"could not write {folder / name}")

    board = default_board()  # what `prism board` prints by default
    setup = station_setup(_STATION_SEED, board=board)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "board.json").write_text(json.dumps(board.describe(), indent=2) + "\n")
    empty = station_scene(_STATION_SEED, setup, parts=0)
    save("plane.jpg", empty.plate)  # the board lies on the support in every render
    save("empty.jpg", empty.plate)
    for i, view in enumerate(calibration_views(setup, _CALIBRATION_VIEWS, 1), 1):
        save(f"calib/{i:02d}.jpg", view)
    truth: list[tuple[str, StationBox]] = []
    for i, part_seed in enumerate(_PART_SEEDS, 1):
        scene = station_scene(part_seed, setup, max_size_mm=150)
        assert scene.box is not None
        save(f"parts/{i}.jpg", scene.photo)
        truth.append((f"parts/{i}.jpg", scene.box))
    for i, box in enumerate(reference_placements(setup), 1):
        scene = station_scene(100 + i, setup, box=box)
        save(f"reference/{i}.jpg", scene.photo)
        truth.append((f"reference/{i}.jpg", box))
    centre = reference_placements(setup)[2]
    save("moved.jpg", station_scene(_MOVED_SEED, turned(setup, MOVED_PX), box=centre, nudge=False).photo)
    truth.append(("moved.jpg", centre))
    held = station_scene(
        _HELD_SEED, station_setup(_HELD_SEED, board=board), nudge=False, inside_board=True, max_size_mm=60
    )
    assert held.box is not None
    save("handheld.jpg", held.photo)
    truth.append(("handheld.jpg", held.box))
    with (folder / "true_sizes.csv").open("w", newline="") as sink:
        writer = csv.writer(sink)
        # as the station reports them: width >= depth, the longer side's yaw
        writer.writerow(["photo", "width_mm", "depth_mm", "height_mm", "x_mm", "y_mm", "yaw_deg"])
        for name, box in truth:
            d = box.dimensions
            yaw = (box.yaw_deg + (90 if box.length_mm < box.width_mm else 0)) % 180
            sizes = (round(d[k], 2) for k in ("width", "depth", "height"))
            writer.writerow([name, *sizes, round(box.x_mm, 1), round(box.y_mm, 1), round(yaw, 1)])
    from rich.console import Console

    rw, rd, rh = REFERENCE_MM
    bw, bh = board.size_mm
    Console().print(
        f"example station (renders): board {bw:g} x {bh:g} mm, camera {setup.distance_mm:.0f} mm from it\n"
        f"     board: {folder / 'board.json'}\n"
        f"     plane: {folder / 'plane.jpg'} (the board on the support)\n"
        f"     empty: {folder / 'empty.jpg'} (the empty support)\n"
        f"     calib: {folder / 'calib'}/ ({_CALIBRATION_VIEWS} poses of the board)\n"
        f"     parts: {folder / 'parts'}/ ({len(_PART_SEEDS)} parts; true sizes in "
        f"{folder / 'true_sizes.csv'})\n"
        f" reference: {folder / 'reference'}/ (a {rw:g} x {rd:g} x {rh:g} mm part, width x depth x height, "
        f"placed {len(_PLACES)} times)\n"
        f"     moved: {folder / 'moved.jpg'} (the reference after the camera turned {MOVED_PX:g} px)\n"
        f"  handheld: {folder / 'handheld.jpg'} (a part on the board, for prism scan --board)",
        soft_wrap=True,
    )

"""`prism board` and `prism station calibrate`: a printable calibration board, and a station (a
camera calibrated to the support parts stand on) made from photos of it."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, cast

import typer

from prismcore import InputError

from .console import rich_console

if TYPE_CHECKING:
    import numpy as np
    from rich.console import Console

    from prismcore.station import BoardSpec, Station

__all__ = ["board", "load_board", "load_station", "station_app"]


def console() -> Console:
    """The command's console (soft wrap: a list of photo names stays on its line)."""
    return rich_console(soft_wrap=True)

station_app = typer.Typer(
    no_args_is_help=True, rich_markup_mode=None,
    help="A station: a camera calibrated to the support parts stand on (measure with prism scan --station).",
)

_PDF_DPI = 300


def _squares(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise InputError(f"--squares {text!r}: expected COLSxROWS squares, e.g. 7x5")
    return int(match[1]), int(match[2])


def load_board(path: Path) -> BoardSpec:
    """board.json as a BoardSpec; a bad file exits 2 naming the field."""
    from pydantic import ValidationError

    from prismcore.station import BoardSpec

    try:
        return BoardSpec.model_validate(json.loads(path.read_text()))
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not JSON ({exc.msg}, line {exc.lineno})") from None
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "board"
        raise InputError(f"{path}: {where}: {first['msg'].removeprefix('Value error, ')}") from None


def load_station(path: Path) -> Station:
    from pydantic import ValidationError

    from prismcore.station import Station

    try:
        return Station.model_validate_json(path.read_text())
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "station"
        raise InputError(f"{path}: not a station.json ({where}: {first['msg']})") from None


def _pdf(board_png: np.ndarray, spec: BoardSpec, paper: str, path: Path) -> None:
    """The board at 1:1 on `paper` (landscape), a 100 mm check ruler and its parameters beside it."""
    import numpy as np
    from PIL import Image, ImageDraw

    from prismcore.station import PAPER_MM

    h_mm, w_mm = PAPER_MM[paper]
    px = _PDF_DPI / 25.4
    page = Image.new("L", (round(w_mm * px), round(h_mm * px)), 255)
    bw, bh = spec.size_mm
    size = (round(bw * px), round(bh * px))
    art = Image.fromarray(np.asarray(board_png)).resize(size, Image.Resampling.NEAREST)
    x0, y0 = round((w_mm - bw) / 2 * px), round(12 * px)
    page.paste(art, (x0, y0))
    draw = ImageDraw.Draw(page)
    ry = y0 + art.height + round(8 * px)
    rx = x0
    draw.line([(rx, ry), (rx + round(100 * px), ry)], fill=0, width=3)
    for mm in range(0, 101, 10):
        tick = round((4 if mm % 50 else 7) * px)
        draw.line([(rx + round(mm * px), ry), (rx + round(mm * px), ry - tick)], fill=0, width=3)
    text = (
        f"100 mm check ruler: measure it after printing (print at 100 %, no fit to page).   "
        f"ChArUco {spec.squares_x}x{spec.squares_y} squares of {spec.square_mm:g} mm, markers "
        f"{spec.marker_mm:g} mm, {spec.dictionary}; board {bw:g} x {bh:g} mm"
    )
    draw.text((rx, ry + round(3 * px)), text, fill=0, font_size=round(2.6 * px))
    page.save(path, "PDF", resolution=_PDF_DPI)


def board(
    out: Annotated[Path, typer.Option(help="Folder for board.png, board.pdf and board.json.")],
    paper: Annotated[str, typer.Option(help="Paper the PDF is for: A4, A3 or letter (landscape).")] = "A4",
    squares: Annotated[str, typer.Option(help="Squares COLSxROWS.")] = "7x5",
    px_per_mm: Annotated[float, typer.Option(help="board.png's resolution.", min=1, max=40)] = 10.0,
) -> None:
    """Write a ChArUco calibration board: board.png (its area exactly), board.pdf (printable at 1:1,
    with a 100 mm check ruler) and board.json (what prism station calibrate reads)."""
    import cv2

    from prismcore.station import board_image, default_board

    spec = default_board(paper, _squares(squares))
    spec = spec.model_copy(update={"png_px_per_mm": px_per_mm})
    image = board_image(spec, px_per_mm)
    out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out / "board.png"), image)
    _pdf(image, spec, paper, out / "board.pdf")
    (out / "board.json").write_text(json.dumps(spec.describe(), indent=2) + "\n")
    w, h = spec.size_mm
    console().print(
        f"ChArUco {spec.squares_x}x{spec.squares_y}, squares {spec.square_mm:g} mm, markers "
        f"{spec.marker_mm:g} mm ({spec.dictionary}): {w:g} x {h:g} mm on {paper}"
    )
    for name in ("board.png", "board.pdf", "board.json"):
        console().print(f"{name:>10}: {out / name}")


@station_app.command("calibrate")
def calibrate(
    board_file: Annotated[
        Path,
        typer.Option(
            "--board", help="board.json (prism board, or any ChArUco board or chessboard described so)."
        ),
    ],
    plane: Annotated[
        Path,
        typer.Option(
            help="The board lying flat on the support, camera in its working position: the station's frame."
        ),
    ],
    out: Annotated[Path, typer.Option(help="station.json to write.")],
    photos: Annotated[
        list[Path] | None,
        typer.Argument(help="Photos of the board in several poses (for the camera's intrinsics and lens)."),
    ] = None,
    camera: Annotated[
        Path | None,
        typer.Option(
            help="camera.json (prism calibrate): known intrinsics; then no calibration photos are needed."
        ),
    ] = None,
    plate: Annotated[
        Path | None,
        typer.Option(
            help="The empty support from the working position (the background parts are found against)."
        ),
    ] = None,
) -> None:
    """Calibrate a station: the camera's intrinsics and lens, the support plane, the plate."""
    from pydantic import ValidationError

    from prismcore.camera import CameraModel
    from prismcore.io import load_image
    from prismcore.station import calibrate_station

    spec = load_board(board_file)
    cam = None
    if camera is not None:
        try:
            cam = CameraModel.model_validate_json(camera.read_text())
        except ValidationError as exc:
            raise InputError(f"{camera}: not a camera.json ({exc.errors()[0]['msg']})") from None
    elif not photos:
        raise InputError("give calibration photos of the board (several poses) or --camera camera.json")
    station = calibrate_station(
        spec,
        load_image(plane),
        [(str(p), load_image(p)) for p in photos or []],
        camera=cam,
        plate=load_image(plate) if plate is not None else None,
        plane_name=str(plane),
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(station.model_dump_json(indent=2) + "\n")
    info, c = station.calibration, station.camera
    if info.get("source") == "photos":
        # station.json's calibration (written by calibrate_station): views and views_left_out are
        # lists of the photos' names
        views = cast("list[str]", info["views"])
        console().print(
            f"camera: fx {c.fx:.1f} fy {c.fy:.1f} px, centre ({c.cx:.1f}, {c.cy:.1f}), "
            f"RMS {info['rms_px']:.3f} px over {info['corners']} corners of {len(views)} photos"
        )
        for name in cast("list[str]", info.get("views_left_out", [])):
            console().print(f"[yellow]left out:[/] {name} (too few board corners)")
    else:
        console().print(f"camera: from {camera} (fx {c.fx:.1f} px)")
    centre = station.plane.camera_centre()
    console().print(
        f"plane: {station.plane.corners} corners, RMS {station.plane.rms_px:.3f} px; camera "
        f"{-centre[2]:.0f} mm above the support"
    )
    from prismcore.station import capability_lines

    for line in capability_lines(station):
        console().print(line, markup=False)
    if station.plate_png is None:
        console().print(
            "[yellow]warning:[/] no --plate: prism scan --station needs a photo of the empty support"
        )
    console().print(f"station: {out}")


@station_app.command("show")
def show(
    station_file: Annotated[
        Path, typer.Argument(metavar="station", help="station.json (prism station calibrate).")
    ],
) -> None:
    """What a station.json holds: its camera, support plane and plate, its capability (mm per pixel
    at the support's near and far edge, the smallest part and tolerance it can hold) and its
    verification (verified on DATE with each dimension's bias and repeatability, or not verified)."""
    from prismcore.station import capability_lines, verification_status

    station = load_station(station_file)
    c, info = station.camera, station.calibration
    out = console()
    rms = f", RMS {info['rms_px']:.3f} px" if isinstance(info.get("rms_px"), (int, float)) else ""
    out.print(f"camera: {c.image_width}x{c.image_height} px, fx {c.fx:.1f} fy {c.fy:.1f} px "
              f"(from {info.get('source', 'photos')}{rms})", markup=False)
    centre = station.plane.camera_centre()
    out.print(f"plane: {station.plane.corners} corners, RMS {station.plane.rms_px:.3f} px; camera "
              f"{-centre[2]:.0f} mm above the support; plate {'stored' if station.plate_png else 'missing'}",
              markup=False)
    w, h = station.board.size_mm
    out.print(f"board: {w:g} x {h:g} mm", markup=False)
    for line in capability_lines(station):
        out.print(line, markup=False)
    status = verification_status(station.verification, moved=False)
    out.print(f"verification: {status['text']}", markup=False)
    v = station.verification
    if v is not None:
        ref = " x ".join(f"{x:g}" for x in v.reference_mm.values())
        tol = "no tolerance" if v.tolerance_mm is None else f"tolerance +-{v.tolerance_mm:g} mm"
        out.print(f"  reference {ref} mm (width x depth x height), {len(v.photos)} placements, {tol}",
                  markup=False)
        for failure in v.decided_by:
            out.print(f"  {failure}", markup=False)

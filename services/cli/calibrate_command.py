"""`prism calibrate`: a camera model (intrinsics, lens distortion) from photos of a chessboard."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prismcore.errors import InputError

from .console import rich_console

if TYPE_CHECKING:
    import numpy as np
    from rich.console import Console

__all__ = ["calibrate", "parse_board"]


def console() -> Console:
    """The command's console (soft wrap: a list of photo names stays on its line)."""
    return rich_console(soft_wrap=True)


# prismcore.io.images.DEFAULT_MAX_PIXELS, not imported for --help (it loads OpenCV; the
# calibration, scipy): tests/cli/test_cli_imports.py checks the two agree.
DEFAULT_MAX_PIXELS = 50_000_000


_IMAGE_SUFFIXES = {".bmp", ".jpg", ".jpeg", ".png", ".tif", ".tiff", ".webp"}
_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


def parse_board(text: str) -> tuple[int, int]:
    """'9x6' -> (9, 6): inner corners per row, per column."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX*]\s*(\d+)\s*", text)
    if not match:
        raise InputError(f"--board {text!r}: expected COLSxROWS inner corners, e.g. 9x6")
    cols, rows = int(match[1]), int(match[2])
    if cols < 3 or rows < 3:
        raise InputError(f"--board {text!r}: expected at least 3x3 inner corners")
    return cols, rows


def _positive_mm(text: str) -> float:
    # parsed here rather than by typer, whose message does not quote the value
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"--square-mm {text!r}: expected a positive length in mm")
    return value


def _photo_paths(images: list[Path]) -> list[Path]:
    paths: list[Path] = []
    for item in images:
        if item.is_dir():
            inside = sorted(p for p in item.iterdir() if p.is_file() and p.suffix.lower() in _IMAGE_SUFFIXES)
            if not inside:
                kinds = ", ".join(sorted(_IMAGE_SUFFIXES))
                raise InputError(f"folder {str(item)!r} holds no photos ({kinds})")
            paths.extend(inside)
        else:
            paths.append(item)
    return paths


def _photos(paths: list[Path], max_pixels: int) -> Iterator[tuple[str, np.ndarray]]:
    from prismcore.io import load_image

    for path in paths:  # one decoded photo in memory at a time
        yield str(path), load_image(path, max_pixels=max_pixels)


def _short_names(names: tuple[str, ...]) -> dict[str, str]:
    """File names alone when they tell the photos apart, else the paths as given."""
    bare = {n: Path(n).name for n in names}
    return bare if len(set(bare.values())) == len(bare) else {n: n for n in names}


def calibrate(
    images: Annotated[list[Path], typer.Argument(help="Photos of the chessboard (or folders of them), "
                                                      "one camera at one size, the board tilted "
                                                      "differently in each.")],
    board: Annotated[str, typer.Option(help="Inner corners COLSxROWS (a board of 10x7 squares is 9x6).")],
    square_mm: Annotated[str, typer.Option(help="Side of one square, mm.")],
    out: Annotated[Path, typer.Option(help="Camera model JSON to write.")] = Path("camera.json"),
    name: Annotated[str | None, typer.Option(help="Free text kept in the model (camera, lens).")] = None,
    max_pixels: Annotated[int, typer.Option(help="Refuse larger images.")] = DEFAULT_MAX_PIXELS,
) -> None:
    """Calibrate a camera from photos of a printed chessboard; write its model for `prism scan --camera`."""
    import numpy as np

    from prismcore.geometry import calibrate_images

    cols_rows = parse_board(board)
    square = _positive_mm(square_mm)
    paths = _photo_paths(images)
    result = calibrate_images(_photos(paths, max_pixels), cols_rows, square)
    camera = result.camera.model_copy(update={"name": name}) if name else result.camera
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(camera.model_dump_json(indent=2) + "\n")

    short = _short_names(result.views + result.missing)
    worst = int(np.argmax(result.per_view_rms_px))
    console().print(f"[bold]RMS reprojection error {result.rms_px:.3f} px[/]  (worst view "
                  f"{short[result.views[worst]]}: {result.per_view_rms_px[worst]:.3f} px)")
    sx, sy = result.focal_sigma_px
    console().print(f"focal length   fx {camera.fx:.2f} +- {sx:.2f} px, fy {camera.fy:.2f} +- {sy:.2f} px")
    console().print(f"principal point {camera.cx:.2f}, {camera.cy:.2f} px  "
                  f"({camera.image_width}x{camera.image_height} photos)")
    console().print("distortion     " + "  ".join(f"{n} {v:+.5f}" for n, v in zip(_DIST_NAMES, camera.dist,
                                                                               strict=False)))
    used = ", ".join(short[v] for v in result.views)
    console().print(f"views used     {result.views_used} of {len(paths)}: {used}")
    if result.missing:
        console().print(f"[yellow]no board in[/] {', '.join(short[v] for v in result.missing)}")
    console().print(f"  camera: {out}")

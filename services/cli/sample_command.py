"""`prism sample`: render a synthetic photo of a box of known size, with its job spec."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from prismcore.errors import InputError

__all__ = ["sample"]


def sample(
    out: Annotated[Path, typer.Option(help="Folder for box.jpg and job.json.")],
    width_mm: Annotated[float, typer.Option(help="Box width.")] = 120.0,
    height_mm: Annotated[float, typer.Option(help="Box height.")] = 80.0,
    depth_mm: Annotated[float, typer.Option(help="Box depth.")] = 60.0,
    seed: Annotated[int, typer.Option(help="Scene seed.")] = 1,
) -> None:
    """Render an oblique photo of a box and write a spec that measures it."""
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

    Console().print(f"true size {width_mm:g} x {height_mm:g} x {depth_mm:g} mm\n"
                    f" image: {out / 'box.jpg'}\n  spec: {out / 'job.json'}")

"""`prism scan A.jpg B.jpg ... --points-file points.json`: several photos of one part as ONE box.

The points file holds one entry per photo: a JSON list in the photos' order, or an object keyed by
the photos' file names (as given, or their base names). An entry is the seven points
``[[x1, y1], ..., [x7, y7]]``, or ``{"points": [...], "side_face": "right|left|top"}``.
`prism scan --spec job.json` with `views` (each photo's path relative to the spec file) does the
same. The result (`prismcore.multiview.joint.fit_views`) is printed (each dimension ± its
sigma, the focal length, the views left out and why) and written to ``joint.json`` in the output folder.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich.markup import escape

from prismcore import InputError, outputs
from prismcore.io import load_image
from prismcore.multiview import JointResult, View, fit_views, joint_report
from prismcore.quality import quality_from_report
from prismcore.spec import PART_FORMATS, KnownEdge, ScanSpec

from .console import rich_console as console
from .outputs import FolderSink

__all__ = ["read_points_file", "scan_spec_views", "scan_views"]


def _entry(entry: Any, where: str) -> tuple[list[list[float]], str]:
    side = "auto"
    if isinstance(entry, dict):
        side = entry.get("side_face", "auto")
        if side not in ("auto", "right", "left", "top"):
            raise InputError(f"{where}: side_face {side!r} is not right, left or top")
        entry = entry.get("points")
    if not isinstance(entry, list) or len(entry) != 7:
        got = f"{len(entry)} entries" if isinstance(entry, list) else repr(entry)[:40]
        raise InputError(f"{where}: expected seven [x, y] points P1..P7, got {got}")
    points = []
    for k, p in enumerate(entry):
        if not (isinstance(p, list) and len(p) == 2 and all(isinstance(v, int | float) for v in p)):
            raise InputError(f"{where}: P{k + 1} {p!r} is not [x, y] in image pixels")
        points.append([float(p[0]), float(p[1])])
    return points, side


def read_points_file(path: Path, images: list[Path]) -> list[tuple[list[list[float]], str]]:
    """The points and side face of each photo, in the photos' order (InputError naming the file,
    the photo or the entry when it does not fit)."""
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"cannot read --points-file {str(path)!r}: {exc.strerror}") from None
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise InputError(f"--points-file {str(path)!r} is not JSON") from None
    if isinstance(data, list):
        if len(data) != len(images):
            raise InputError(f"--points-file {str(path)!r} has {len(data)} entries for {len(images)} "
                             "photos: give one per photo, in their order")
        return [_entry(e, f"--points-file entry {k + 1} ({images[k].name})") for k, e in enumerate(data)]
    if isinstance(data, dict):
        out = []
        for image in images:
            key = next((k for k in (str(image), image.name) if k in data), None)
            if key is None:
                raise InputError(f"--points-file {str(path)!r} has no entry for {image.name!r}")
            out.append(_entry(data[key], f"--points-file entry {key!r}"))
        return out
    raise InputError(f"--points-file {str(path)!r}: expected a list of entries or an object keyed by "
                     "the photos' names")


def result_json(result: JointResult) -> dict[str, Any]:
    """joint.json: the dimensions with their sigma, the camera, each view, the views left out."""
    return joint_report(result)


def write_part_files(report: dict[str, Any], scale: KnownEdge, formats: Sequence[str], out: Path,
                     nominal: Any = None, tolerance_mm: Any = None) -> dict[str, Path]:
    """The part's files of `formats` (step, drawing, stl: the others make no sense without a cloud)
    from a joint fit's report, with its verdicts against `nominal` and its scale; {kind: path}."""
    measured = {**report, "quality": quality_from_report(report, nominal, tolerance_mm),
                "inputs": {"scale": scale.model_dump()}}
    names = outputs.write_part_files(measured, [f for f in formats if f in PART_FORMATS], FolderSink(out))
    return {kind: out / name for kind, name in names.items()}


def scan_views(images: list[Path], points_file: Path, out: Path, scale: dict[str, Any] | None,
               focal_px: float | None, max_pixels: int, formats: list[str] | None = None) -> None:
    """Measure the photos as one box; print the result and write ``out/joint.json`` (and the
    part's step, drawing and stl files when `formats` asks for them: a joint fit makes no cloud)."""
    asked = [f for f in formats or [] if f not in ("csv", "ply")]
    if any(f not in PART_FORMATS for f in asked):
        raise InputError(f"--format {','.join(formats or [])!r}: several photos measured as one box make "
                         "no cloud; --format takes step and drawing (the part's solid and drawing) "
                         "and stl (its mesh)")
    if scale is None or scale.get("kind") != "edge":
        raise InputError("several photos are measured with one known edge: give --width-mm, "
                         "--height-mm or --depth-mm")
    entries = read_points_file(points_file, images)
    views = [View(load_image(path, max_pixels=max_pixels), points, side, path.name)
             for path, (points, side) in zip(images, entries, strict=True)]
    _measure(views, KnownEdge.model_validate(scale), focal_px, out, asked)


def scan_spec_views(spec: ScanSpec, base: Path, out: Path) -> None:
    """`prism scan --spec` of a spec with views (paths relative to `base`): as `scan_views`."""
    assert spec.views is not None and isinstance(spec.scale, KnownEdge)  # the spec's rules
    views = [View(load_image(base / v.image, max_pixels=spec.max_pixels), v.points, v.side_face,
                  v.name or Path(v.image).name) for v in spec.views]
    _measure(views, spec.scale, spec.focal_px, out, spec.part_formats, spec.nominal, spec.tolerance_mm)


def _measure(views: list[View], scale: KnownEdge, focal_px: float | None, out: Path,
             formats: Sequence[str] | None = None, nominal: Any = None, tolerance_mm: Any = None) -> None:
    result = fit_views(views, scale, focal_px=focal_px)
    out.mkdir(parents=True, exist_ok=True)
    report = result_json(result)
    (out / "joint.json").write_text(json.dumps(report, indent=2) + "\n")
    paths = write_part_files(report, scale, formats or [], out, nominal, tolerance_mm)
    d = result.dimensions
    assert d.uncertainty is not None
    # The known edge is its length, given: "120.00 (given)", not a measurement "± 0.00".
    sizes = " x ".join(f"{v:.2f} (given)" if name == scale.edge else f"{v:.2f} ± {s:.2f}"
                       for name, v, s in zip(("width", "height", "depth"), (d.width, d.height, d.depth),
                                             d.uncertainty, strict=True))
    focal = (f"focal {result.focal_px:.0f} ± {result.focal_std_px:.0f} px (fitted)"
             if result.focal_std_px is not None else f"focal {result.focal_px:.0f} px (given)")
    console().print(f"[bold]{len(result.views)} of {len(views)} views as one box[/]  {sizes} mm  {focal}",
                  soft_wrap=True)
    for left in result.left_out:
        console().print(f"[yellow]left out[/] {escape(left.name)}: {escape(left.reason)}", soft_wrap=True)
    for warning in (*result.warnings, *d.notes):
        console().print(f"[yellow]warning[/] {escape(warning)}", soft_wrap=True)
    for kind, path in paths.items():
        console().print(f"{kind}: {path}", soft_wrap=True)

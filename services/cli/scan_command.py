"""`prism scan`: run one scan locally, from flags or a spec file (a photo, or a video's frames)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prismcore.errors import InputError
from prismcore.formats import FORMATS, METRIC_FORMATS

from .scan_flags import (
    one_line,
    quality_flags,
    read_spec_json,
    scale_from_flags,
    scale_options,
    selection_from_flags,
    spec_from_flags,
)
from .scan_runners import RUNNERS, RunOptions

if TYPE_CHECKING:
    from prismcore.camera import CameraModel
    from prismcore.spec import ScanSpec

# The engine (numpy, OpenCV, scipy) and pydantic are imported where a command runs, not here:
# `prism --help` and every other command import this module (tests/cli/test_cli_imports.py).

# prismcore.video.frame_select.DEFAULT_MAX_FRAMES (importing it loads OpenCV for --help);
# tests/cli/test_cli_imports.py checks the two agree.
DEFAULT_MAX_FRAMES = 500

# The formats in pixels, from the format table: --format's help names them.
_NO_SCALE = " and ".join(f for f in FORMATS if f not in METRIC_FORMATS)

__all__ = ["scan"]


def _camera_file(path: Path) -> CameraModel:
    from pydantic import ValidationError

    from prismcore.camera import CameraModel

    try:
        return CameraModel.model_validate_json(path.read_text())
    except OSError as exc:
        raise InputError(f"cannot read --camera {str(path)!r}: {exc.strerror}") from None
    except ValidationError as exc:
        raise InputError(f"--camera {str(path)!r} is not a camera model (prism calibrate writes "
                         f"one): {one_line(exc)}") from None


def _spec_from_file(path: Path) -> tuple[ScanSpec, Path]:
    from prismcore.spec import ScanSpec

    return ScanSpec.model_validate(read_spec_json(path)), path.parent


def scan(
    out: Annotated[Path, typer.Option(help="Folder for cloud.csv, cloud.ply, report.json and overlay.jpg "
                                           "(a video: one folder per frame and summary.json).")],
    image: Annotated[list[Path] | None, typer.Argument(
        help="Front photo (or the only photo), or a video; several photos of one part with "
             "--points-file (measured as one box); a batch of parts, one a photo, with --station, "
             "--board or --points-table.")] = None,
    points_file: Annotated[Path | None, typer.Option(
        help="Several photos of one part: JSON with one entry of seven points per photo (a list in "
             "their order, or keyed by file name; an entry may be {\"points\": [...], \"side_face\": "
             "\"top\"}): the photos are measured as ONE box (one known edge), joint.json in --out.")] = None,
    points_table: Annotated[Path | None, typer.Option(
        help="A batch of parts, one a photo, each with its own points: a CSV table with a header, "
             "columns file and points (\"x1,y1 x2,y2 ...\" or auto), and any of reference, width_mm, "
             "height_mm, depth_mm, distance_mm, mm_per_px, focal_px, side_face, nominal, tolerance_mm "
             "(a row's own; else the options'). The photos given (found by path or name), else every "
             "row's (relative to the table).")] = None,
    points: Annotated[str | None, typer.Option(
        help='"x1,y1 x2,y2 x3,y3 x4,y4 x5,y5 [x6,y6 x7,y7]" in image pixels, or auto (found in '
             'the photo; refused, exit 2, when not sure).')] = None,
    hint: Annotated[str | None, typer.Option(help="--points auto: X,Y px on the box wanted.")] = None,
    roi: Annotated[str | None, typer.Option(
        help="--points auto: X0,Y0,X1,Y1 px, the region to look in.")] = None,
    side: Annotated[Path | None, typer.Option(help="Side photo (two-photo mode).")] = None,
    side_face: Annotated[str | None, typer.Option(
        help="One photo: the face P4, P5 (P7) mark besides the front: right (P4 = P2), left "
             "(P4 = P1, P5 left of it) or top (P4 = P1, P5 above it); default: read from the points.",
        metavar="right|left|top")] = None,
    spec_file: Annotated[Path | None, typer.Option("--spec", help="Job spec JSON.")] = None,
    tolerance: Annotated[float, typer.Option(help="RGB tolerance per channel.")] = 12.0,
    method: Annotated[str, typer.Option(help="default or paper.")] = "default",
    mm_per_px: Annotated[str | None, typer.Option(help="F, or FRONT,SIDE for two photos.")] = None,
    distance_mm: Annotated[float | None, typer.Option(help="Shooting distance, mm.")] = None,
    focal_px: Annotated[float | None, typer.Option(help="Focal length, pixels.")] = None,
    camera: Annotated[Path | None, typer.Option(
        help="camera.json from prism calibrate: intrinsics and lens distortion.")] = None,
    width_mm: Annotated[float | None, typer.Option(help="Known real width.")] = None,
    height_mm: Annotated[float | None, typer.Option(help="Known real height.")] = None,
    depth_mm: Annotated[float | None, typer.Option(help="Known real depth.")] = None,
    cloud: Annotated[str, typer.Option(help="surface or volume.")] = "surface",
    formats: Annotated[str, typer.Option(
        "--format", help=f"Any of {','.join(FORMATS)} (las/laz: the cloud in metres, Z "
                         "up; glb: the box textured from the photo; step: the part as a STEP solid, "
                         "part.step and part.step.json; drawing: its inspection drawing, drawing.svg, "
                         f".pdf and .dxf; stl: the box as a mesh; all but {_NO_SCALE} need a "
                         "scale).")] = "csv,ply",
    spacing_mm: Annotated[float | None, typer.Option(
        help="Thin the cloud to about this spacing, mm (default: one point per pixel).")] = None,
    nominal: Annotated[str | None, typer.Option(
        help="Nominal W,H,D in mm: each dimension gets a pass/fail/uncertain verdict.",
        metavar="W,H,D")] = None,
    tolerance_mm: Annotated[str | None, typer.Option(
        help="Allowed deviation from --nominal, mm: T, or Tw,Th,Td.", metavar="T")] = None,
    csv_header: Annotated[bool, typer.Option(help="Header line in the CSV.")] = False,
    csv_colors: Annotated[bool, typer.Option(help="r,g,b columns in the CSV.")] = False,
    ply_ascii: Annotated[bool, typer.Option(help="ASCII PLY instead of binary.")] = False,
    overlay_format: Annotated[str, typer.Option(
        help="The fit drawn on the photo as jpeg (overlay.jpg), png (lossless, overlay.png) or webp.",
        metavar="jpeg|png|webp")] = "jpeg",
    max_pixels: Annotated[int, typer.Option(help="Refuse larger images.")] = 50_000_000,
    tiles: Annotated[int, typer.Option(help="Row bands per face (same result).", min=1)] = 1,
    every: Annotated[int | None, typer.Option(help="Video: every Nth frame.")] = None,
    start: Annotated[float | None, typer.Option(help="Video: from this time, s.")] = None,
    end: Annotated[float | None, typer.Option(help="Video: up to this time, s.")] = None,
    frame_list: Annotated[str | None, typer.Option("--frames", help="Video: frame indices 0,5,9.")] = None,
    sharpest: Annotated[int | None, typer.Option(help="Video: the K sharpest frames.")] = None,
    max_frames: Annotated[int, typer.Option(help="Video: most frames measured.", min=1)] = DEFAULT_MAX_FRAMES,
    station: Annotated[Path | None, typer.Option(
        help="station.json (prism station calibrate): the part measured on the station, no points and "
             "no known edge needed.")] = None,
    board: Annotated[Path | None, typer.Option(
        help="board.json of the board the part lies on, hand-held (no station): the board in the photo "
             "gives the scale, and the focal length unless --camera.")] = None,
    points_frame: Annotated[int | None, typer.Option(
        help="Video, hand-held: the frame --points were marked on; they are tracked to every selected "
             "frame (tracked_points.json in --out).", min=0)] = None,
    fit: Annotated[str | None, typer.Option(
        help="Video with --points-frame: frames (each frame measured, summary.json) or joint (the "
             "tracked frames as ONE box, joint.json; needs a known edge).", metavar="frames|joint")] = None,
) -> None:
    """Turn a photo (or a front and a side photo, or a video's frames) of a box into measured point clouds;
    several photos of one part with --points-file: measured as one box.

    A batch in one process, one part a photo: several photos with --station (or --board), or
    --points-table. Each photo's outputs go to DIR/NAME/ (NAME: the photo's name without its
    suffix), one line is printed as each finishes, and DIR/results.csv and results.json hold a row
    per photo (the service's results columns). A photo that fails is named with its reason and the
    others are measured; exit 1 if any failed, 2 for bad input (nothing measured).
    """
    started = time.perf_counter()
    from pydantic import ValidationError

    images = image or []
    if overlay_format not in ("jpeg", "png", "webp"):
        raise InputError(f"--overlay-format {overlay_format!r}: expected jpeg, png or webp")
    if points_table is not None or ((station is not None or board is not None) and len(images) > 1):
        if points_table is not None and (station is not None or board is not None):
            raise InputError("--points-table gives each photo its points: not with --station or --board")
        clash = [flag for flag, value in (
            ("--points", points if points_table is not None else None), ("--points-file", points_file),
            ("--spec", spec_file), ("--side", side), ("--points-frame", points_frame), ("--fit", fit),
            ("--hint", hint), ("--roi", roi)) if value is not None]
        if clash:
            raise InputError(f"a batch (one part a photo) does not take {', '.join(clash)}")
        from .batch_command import board_batch, station_batch, table_batch

        if points_table is not None:
            failed = table_batch(images, points_table, out, spec_flags=dict(
                tolerance=tolerance, method=method, mm_per_px=mm_per_px, distance_mm=distance_mm,
                focal_px=focal_px, width_mm=width_mm, height_mm=height_mm, depth_mm=depth_mm, cloud=cloud,
                formats=formats, csv_header=csv_header, csv_colors=csv_colors, ply_ascii=ply_ascii,
                max_pixels=max_pixels, side_face=side_face or "auto", spacing_mm=spacing_mm,
                nominal=nominal, tolerance_mm=tolerance_mm), run=RunOptions(
                out=out, camera=(lambda: _camera_file(camera)) if camera is not None else None,
                tiles=tiles, max_frames=max_frames, overlay_format=overlay_format, started=started))
        elif station is not None:
            judged = quality_flags(nominal, tolerance_mm)
            failed = station_batch(images, station, out, formats=formats, max_pixels=max_pixels,
                                   overlay_format=overlay_format, tolerance_mm=judged.get("tolerance_mm"),
                                   nominal=judged.get("nominal"))
        else:
            assert board is not None
            failed = board_batch(images, board, out, camera=_camera_file(camera) if camera else None,
                                 formats=formats, max_pixels=max_pixels, overlay_format=overlay_format)
        if failed:
            raise typer.Exit(1)
        return
    if station is not None or board is not None:
        flag = "--station" if station is not None else "--board"
        if station is not None and board is not None:
            raise InputError("give --station (a calibrated station) or --board (hand-held), not both")
        if len(images) != 1 or spec_file is not None or points_file is not None or side is not None:
            raise InputError(f"{flag} measures one photo: prism scan PHOTO {flag} FILE --out DIR")
        if points not in (None, "auto"):
            raise InputError(f"{flag} finds the points itself: drop --points (or give --points auto)")
        scales = (mm_per_px, distance_mm, width_mm, height_mm, depth_mm, focal_px)
        if any(v is not None for v in scales) or (station is not None and camera is not None):
            raise InputError(f"{flag} gives the scale: drop --mm-per-px, --distance-mm, --width-mm/"
                             "--height-mm/--depth-mm and --focal-px" + (" and --camera" if station else ""))
        from .station_scan import scan_on_board_photo, scan_on_station

        if station is not None:
            # the tolerance judges the camera's drift since calibration (prismcore.station.certify)
            judged = quality_flags(nominal, tolerance_mm)
            scan_on_station(images[0], station, out, formats=formats, max_pixels=max_pixels,
                            overlay_format=overlay_format, tolerance_mm=judged.get("tolerance_mm"),
                            nominal=judged.get("nominal"))
        else:
            assert board is not None
            scan_on_board_photo(images[0], board, out, camera=_camera_file(camera) if camera else None,
                                formats=formats, max_pixels=max_pixels, overlay_format=overlay_format)
        return
    if points_file is not None or len(images) > 1:
        if points_file is None:
            raise InputError(f"{len(images)} photos: give --points-file with one entry of points per photo "
                             "to measure them as one box")
        if points is not None or spec_file is not None or side is not None:
            raise InputError("--points-file goes with the photos alone: not with --points, --spec or --side")
        if not images:
            raise InputError("--points-file: give the photos it marks")
        from .joint_scan import scan_views

        try:
            scale = scale_from_flags(mm_per_px, distance_mm, width_mm, height_mm, depth_mm)
            scan_views(images, points_file, out, scale, focal_px, max_pixels,
                       [f.strip() for f in formats.split(",") if f.strip()])
        except ValidationError as exc:
            raise InputError(one_line(exc, scale_options(mm_per_px, distance_mm, width_mm, height_mm,
                                                         depth_mm))) from None
        return
    one: Path | None = images[0] if images else None
    run = RunOptions(out=out, camera=(lambda: _camera_file(camera)) if camera is not None else None,
                     tiles=tiles, max_frames=max_frames, overlay_format=overlay_format, started=started)
    try:
        selection = selection_from_flags(every, start, end, frame_list, sharpest)
        if spec_file is not None:
            if one is not None or points is not None or selection is not None:
                raise InputError("give either --spec or IMAGE with --points (and frame flags), not both")
            if side_face is not None:
                raise InputError(f"--side-face {side_face!r} goes with IMAGE and --points; "
                                 "in a spec file, set side_face")
            if points_frame is not None or fit is not None:
                raise InputError("--points-frame and --fit go with IMAGE and --points; in a spec file, "
                                 "set points_frame and fit")
            for flag, value in (("--nominal", nominal), ("--tolerance-mm", tolerance_mm),
                                ("--spacing-mm", spacing_mm)):
                if value is not None:
                    raise InputError(f"{flag} {value!r} goes with IMAGE and --points; in a spec file, "
                                     f"set {flag[2:].replace('-', '_')}")
            spec, base = _spec_from_file(spec_file)
        else:
            from prismcore.io import is_video

            if selection is None and one is not None and is_video(one):
                selection = {}  # a video without frame flags: every frame, under --max-frames
            spec, base = spec_from_flags(
                one, points, side=side, tolerance=tolerance, method=method,
                mm_per_px=mm_per_px, distance_mm=distance_mm, focal_px=focal_px,
                width_mm=width_mm, height_mm=height_mm, depth_mm=depth_mm, cloud=cloud,
                formats=formats, csv_header=csv_header, csv_colors=csv_colors,
                ply_ascii=ply_ascii, max_pixels=max_pixels, frames=selection,
                side_face=side_face or "auto", spacing_mm=spacing_mm, nominal=nominal,
                tolerance_mm=tolerance_mm, hint=hint, roi=roi, points_frame=points_frame, fit=fit), Path(".")
        RUNNERS[spec.kind](spec, base, run)
    except ValidationError as exc:
        raise InputError(one_line(exc)) from None

"""`prism scan`: run one scan locally, from flags or a spec file (a photo, or a video's frames)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from prismcore.errors import InputError
from prismcore.formats import FORMATS, METRIC_FORMATS

from .scan_runners import RUNNERS, RunOptions

if TYPE_CHECKING:
    from pydantic import ValidationError

    from prismcore.camera import CameraModel
    from prismcore.spec import ScanSpec

# The engine (numpy, OpenCV, scipy) and pydantic are imported where a command runs, not here:
# `prism --help` and every other command import this module (tests/cli/test_cli_imports.py).

# prismcore.video.frame_select.DEFAULT_MAX_FRAMES (importing it loads OpenCV for --help);
# tests/cli/test_cli_imports.py checks the two agree.
DEFAULT_MAX_FRAMES = 500

# The formats in pixels, from the format table: --format's help names them.
_NO_SCALE = " and ".join(f for f in FORMATS if f not in METRIC_FORMATS)

__all__ = ["one_line", "quality_flags", "scale_options", "scan", "selection_from_flags", "spec_from_flags"]



def _internal(step: int | str) -> bool:
    return isinstance(step, str) and ("[" in step or step.startswith(("constrained-", "function-")))


# A bound pydantic names ("Input should be greater than 0") as the option's rule ("must be > 0").
_BOUNDS = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="), "less_than": ("lt", "<"),
           "less_than_equal": ("le", "<=")}


def _option_rule(option: str, first: Mapping[str, Any], message: str) -> str:
    """The error told by the option's name: what its value must be ("--width-mm must be > 0"),
    or the model's own reason after it."""
    bound = _BOUNDS.get(str(first.get("type")))
    ctx = first.get("ctx") or {}
    if bound is not None and bound[0] in ctx:
        return f"{option} must be {bound[1]} {ctx[bound[0]]:g}"
    if first.get("type") == "finite_number":
        return f"{option} must be a finite number"
    return f"{option}: {message}"


def one_line(error: ValidationError, options: Mapping[str, str] | None = None) -> str:
    """A spec's validation error as one line: where, what, how many more. `options` maps a spec
    field ("scale.edge.length_mm") to the command-line option that gave it ("--width-mm"): an
    error there is told by the option's name ("--width-mm must be > 0")."""
    from prismcore.spec import error_message

    first = error.errors()[0]
    # Steps that name pydantic's own validators ("function-after[check(), constrained-float]",
    # a branch of a union) are not in the spec: left out.
    where = ".".join(str(p) for p in first["loc"] if not _internal(p)) or "spec"
    more = f" (and {error.error_count() - 1} more)" if error.error_count() > 1 else ""
    # A validator's message that names its field already ("views: ...") is not prefixed again.
    message = error_message(first["msg"])
    if options and where in options:
        return f"{_option_rule(options[where], first, message)}{more}"
    if message.startswith((f"{where}:", f"{where} ")):
        return f"{message}{more}"
    return f"{where}: {message}{more}"


def _scale(mm_per_px: str | None, distance_mm: float | None, width_mm: float | None,
           height_mm: float | None, depth_mm: float | None) -> dict | None:
    given = [v is not None for v in (mm_per_px, distance_mm, width_mm, height_mm, depth_mm)]
    if sum(given) > 1:
        raise InputError("give one scale: --mm-per-px, --distance-mm, or one of "
                         "--width-mm/--height-mm/--depth-mm")
    if mm_per_px is not None:
        try:
            values = [float(v) for v in mm_per_px.split(",")]
        except ValueError:
            raise InputError(f"--mm-per-px {mm_per_px!r}: expected F or FRONT,SIDE") from None
        if len(values) not in (1, 2):
            raise InputError(f"--mm-per-px {mm_per_px!r}: expected F or FRONT,SIDE")
        return {"kind": "mm_per_px", "front": values[0],
                "side": values[1] if len(values) == 2 else None}
    if distance_mm is not None:
        return {"kind": "pinhole", "distance_mm": distance_mm}
    for edge, length in (("width", width_mm), ("height", height_mm), ("depth", depth_mm)):
        if length is not None:
            return {"kind": "edge", "edge": edge, "length_mm": length}
    return None


def scale_options(mm_per_px: str | None = None, distance_mm: float | None = None,
                  width_mm: float | None = None, height_mm: float | None = None,
                  depth_mm: float | None = None) -> dict[str, str]:
    """The spec fields the scale options fill, each named by its option (for `one_line`); the
    known edge's length also as a lone KnownEdge's field (a joint fit validates it alone)."""
    options = {"focal_px": "--focal-px", "spacing_mm": "--spacing-mm", "max_pixels": "--max-pixels",
               "tolerance": "--tolerance", "scale.pinhole.distance_mm": "--distance-mm",
               "scale.mm_per_px.front": "--mm-per-px", "scale.mm_per_px.side": "--mm-per-px SIDE"}
    for flag, value in (("--width-mm", width_mm), ("--height-mm", height_mm), ("--depth-mm", depth_mm)):
        if value is not None:
            options["scale.edge.length_mm"] = options["length_mm"] = flag
    return options


def _mm_values(flag: str, text: str, counts: tuple[int, ...], expected: str) -> list[float]:
    """'100,80,60' -> [100.0, 80.0, 60.0]; a bad number or count names the flag and the text."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{flag} {text!r}: expected {expected} in mm") from None
    if len(values) not in counts or not all(math.isfinite(v) for v in values):
        raise InputError(f"{flag} {text!r}: expected {expected} in mm")
    return values


def quality_flags(nominal: str | None, tolerance_mm: str | None) -> dict[str, Any]:
    """The spec's `nominal` and `tolerance_mm` from ``--nominal W,H,D --tolerance-mm T|Tw,Th,Td``."""
    if (nominal is None) != (tolerance_mm is None):
        raise InputError("--nominal and --tolerance-mm go together: give both")
    if nominal is None or tolerance_mm is None:
        return {}
    tol = _mm_values("--tolerance-mm", tolerance_mm, (1, 3), "T or Tw,Th,Td")
    sizes = _mm_values("--nominal", nominal, (3,), "W,H,D")
    if min(tol) < 0:
        raise InputError(f"--tolerance-mm {tolerance_mm!r}: a tolerance is >= 0 mm")
    if min(sizes) <= 0:
        raise InputError(f"--nominal {nominal!r}: sizes are > 0 mm")
    return {"nominal": sizes,
            "tolerance_mm": tol[0] if len(tol) == 1 else tol}


def spec_from_flags(image: Path | None, points: str | None, **flags: Any) -> ScanSpec:
    if image is None or points is None:
        raise InputError("give IMAGE and --points, or --spec FILE")
    from prismcore.spec import ScanSpec

    formats = [f.strip() for f in flags.pop("formats", "csv,ply").split(",") if f.strip()]
    given = {k: flags.pop(k, None) for k in ("mm_per_px", "distance_mm", "width_mm", "height_mm", "depth_mm")}
    scale = _scale(**given)
    side = flags.pop("side", None)
    auto = _auto_points(points, flags.pop("hint", None), flags.pop("roi", None))
    flags.update(quality_flags(flags.pop("nominal", None), flags.pop("tolerance_mm", None)))
    from pydantic import ValidationError

    try:
        return ScanSpec.model_validate({
            "image": str(image), "side_image": str(side) if side else None,
            **auto, "scale": scale, "formats": formats,
            "csv": {"header": flags.pop("csv_header", False), "colors": flags.pop("csv_colors", False)},
            **flags,
        })
    except ValidationError as exc:  # a bad option's value: told by the option's name
        raise InputError(one_line(exc, scale_options(**given))) from None


def _numbers(flag: str, text: str, count: int) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        shape = "X,Y" if count == 2 else "X0,Y0,X1,Y1"
        raise InputError(f"{flag} {text!r}: expected {shape} in image pixels")
    return values


def _auto_points(points: str, hint: str | None, roi: str | None) -> dict[str, object]:
    """The spec's points (and auto_points) from --points, --hint and --roi."""
    if points.strip() != "auto":
        if hint is not None or roi is not None:
            raise InputError("--hint and --roi go with --points auto")
        from prismcore.spec import parse_points

        try:
            return {"points": parse_points(points).model_dump()}
        except ValueError as exc:
            raise InputError(f"--points: {exc}") from None
    if hint is not None and roi is not None:
        raise InputError("give --hint or --roi, not both")
    return {"points": "auto", "auto_points": {
        "hint": None if hint is None else _numbers("--hint", hint, 2),
        "roi": None if roi is None else _numbers("--roi", roi, 4)}}


def selection_from_flags(every: int | None, start: float | None, end: float | None,
                         frames: str | None, sharpest: int | None) -> dict | None:
    """The spec's `frames` from the CLI flags; None when no flag was given."""
    selection: dict = {"every": every, "start_s": start, "end_s": end, "sharpest": sharpest}
    if frames is not None:
        try:
            selection["indices"] = [int(v) for v in frames.split(",") if v.strip()]
        except ValueError:
            raise InputError(f"--frames {frames!r}: expected frame indices like 0,5,9") from None
    given = {k: v for k, v in selection.items() if v is not None}
    return given or None


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


def read_spec_json(path: Path) -> Any:
    """A spec file's JSON, or an InputError saying in one line why it cannot be read."""
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"cannot read spec {str(path)!r}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"spec {str(path)!r} is not JSON: {exc.msg} at line {exc.lineno}") from None
    except UnicodeDecodeError:
        raise InputError(f"spec {str(path)!r} is not JSON: not UTF-8 text") from None


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
            scale = _scale(mm_per_px, distance_mm, width_mm, height_mm, depth_mm)
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

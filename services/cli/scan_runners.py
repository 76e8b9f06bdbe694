"""`prism scan`'s runners: one small function per kind of item (`ScanSpec.kind`), and the table
`scan` picks one from.

A runner takes the validated spec, the folder its relative paths are read from and what the
command's other options say (`RunOptions`), checks the options that do not go with its kind, and
hands the spec to the module that measures it (`photo_scan`, `video_scan`, `tracked_scan`,
`joint_scan`). Those modules load the engine (numpy, OpenCV, the fits) and are imported when a
runner runs: `prism --help` imports this module (tests/cli/test_cli_imports.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from prismcore.errors import InputError

if TYPE_CHECKING:
    from prismcore.camera import CameraModel
    from prismcore.spec import ItemKind, ScanSpec

__all__ = ["RUNNERS", "RunOptions"]


@dataclass(frozen=True)
class RunOptions:
    """What `prism scan`'s options say besides the spec: where to write, and how to run."""

    out: Path
    camera: Callable[[], CameraModel] | None  # reads --camera's file, where the kind takes one
    tiles: int
    max_frames: int
    overlay_format: str
    started: float  # time.perf_counter() when the command started: the report's total time


def _with_camera(spec: ScanSpec, run: RunOptions) -> ScanSpec:
    return spec if run.camera is None else spec.model_copy(update={"camera": run.camera()})


def _no_camera(run: RunOptions, known: str) -> None:
    """A joint fit finds its own camera: --camera is refused (`known`: where a known focal goes)."""
    if run.camera is not None:
        raise InputError("--camera does not go with a joint fit: it finds one focal length and "
                         f"lens distortion from the views ({known})")


def run_photo(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    """One photo (or a front and a side photo), its points clicked or found; a spec whose image
    is a video file, though it selects no frames, is measured as a video."""
    from prismcore.io import is_video

    spec = _with_camera(spec, run)
    if is_video(base / spec.image):
        _scan_video(spec, base, run)
        return
    from .photo_scan import scan_photo

    scan_photo(spec, base, run.out, tiles=run.tiles, overlay_format=run.overlay_format,
               started=run.started)


def run_video(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    """A video's selected frames, each measured as a photo."""
    _scan_video(_with_camera(spec, run), base, run)


def _scan_video(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    from .video_scan import scan_video

    scan_video(spec, base, run.out, tiles=run.tiles, max_frames=run.max_frames,
               overlay_format=run.overlay_format)


def run_tracked(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    """Points marked on one frame of a video, tracked to the others (each frame measured, or with
    fit "joint" the tracked frames as one box)."""
    if spec.kind == "tracked_joint":
        _no_camera(run, "give --focal-px if known")
    from .tracked_scan import scan_tracked

    scan_tracked(_with_camera(spec, run), base, run.out, tiles=run.tiles, max_frames=run.max_frames,
                 overlay_format=run.overlay_format)


def run_views(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    """Several photos of one part, each with its seven points, measured as one box."""
    _no_camera(run, "set focal_px in the spec if known")
    from .joint_scan import scan_spec_views

    scan_spec_views(spec, base, run.out)


def run_frames_joint(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    """A video's frames with points each, as one box: the service measures it, not prism scan."""
    _no_camera(run, "set focal_px in the spec if known")
    raise InputError("fit \"joint\" (a video's frames as one box) is measured by the service "
                     "(prism submit); here, give the frames as photos: prism scan A.png B.png "
                     "--points-file points.json")


def run_station(spec: ScanSpec, base: Path, run: RunOptions) -> None:
    """A spec naming a station stored in the service: prism scan measures with a station's file."""
    raise InputError(f"the spec names station {spec.station!r}, a station stored in the service: "
                     "submit it (prism submit), or here give the station's file: "
                     "prism scan PHOTO --station station.json --out DIR")


Runner = Callable[["ScanSpec", Path, RunOptions], None]

RUNNERS: dict[ItemKind, Runner] = {
    "photo": run_photo, "found": run_photo,  # the points found in the photo before it is scanned
    "video": run_video,
    "tracked": run_tracked, "tracked_joint": run_tracked,
    "views": run_views,
    "frames_joint": run_frames_joint,
    "station": run_station,
}
"""The runner of each item kind: the one place `prism scan` tells the kinds apart."""

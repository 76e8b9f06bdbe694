"""The scan as three stages: plan (once), scan tiles (in parallel if wanted), finish (once).

``run_scan`` chains them in one process; the worker runs the same stages as separate tasks.
The camera the fit starts from is `scan.focal`'s; the faces' edges, the box's measure and its
checks are `scan.fit`'s. Images are RGB arrays (H, W, 3): uint8, or float32 in 0-255 units for 16-bit inputs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from prismcore._version import __version__
from prismcore.errors import InputError
from prismcore.geometry.edges import EdgeFit
from prismcore.geometry.faces import SideFace, resolve_side_face
from prismcore.quality.verdicts import report_quality
from prismcore.report import ScanReport
from prismcore.scan.cloud import Cloud, assemble, face_points
from prismcore.scan.colour_scan import FacePlan, FaceScan, merge_bands, row_tiles, scan_band, window_for
from prismcore.scan.fit import EdgeUses, edge_use_json, fit_guard, measure_faces, refine_faces, unless_snapped
from prismcore.scan.focal import PooledFocal, camera_models, prepare_images, resolve_focal, undistorted_points
from prismcore.scan.measure import Dimensions
from prismcore.scan.point_checks import check_points, marked_quads, side_height_guess
from prismcore.scan.spacing import thin_to_spacing
from prismcore.spec import Pinhole, ScanSpec

__all__ = ["ScanPlan", "ScanResult", "build_report", "finish_scan", "plan_scan", "run_scan", "scan_face"]

POINT_LOSS_WARN = 0.2  # warn when a face's cloud lacks more than this share of its marked pixels

SAME_SCALE_ASSUMED = ("two photos, no P7 and a scale for only one of them: the other is taken to be "
                      "at the same scale (shot from the same distance), and the dimensions it gives "
                      "rest on that; mark P7, or give each photo its scale, to measure them")


_GIVE_A_SCALE = ("give a scale to measure in mm: a known edge's length (prism scan --width-mm, --height-mm "
                 "or --depth-mm; a spec's scale kind \"edge\"), millimetres per pixel (--mm-per-px; "
                 "\"mm_per_px\") or the shooting distance (--distance-mm; \"pinhole\")")


def in_pixels_warning(spec: ScanSpec) -> str:
    """The warning of a scan measured without a scale: its figures are pixels, not mm, and how
    to give a scale (a focal length alone is none: it needs the shooting distance)."""
    if spec.focal_px is not None or spec.camera is not None:
        return ("no scale: a focal length without the shooting distance gives none, so the dimensions "
                "are in pixels, not mm; add the distance (--distance-mm; the spec's scale kind "
                "\"pinhole\"), or " + _GIVE_A_SCALE)
    return "no scale given: the dimensions are in pixels, not mm; " + _GIVE_A_SCALE


@dataclass
class ScanPlan:
    """Everything fixed before the tiles run: the faces to scan and the prism's dimensions."""

    spec: ScanSpec
    faces: tuple[FacePlan, FacePlan]
    dimensions: Dimensions
    edges: dict[str, list[EdgeFit]]
    image_sizes: list[tuple[int, int]]
    warnings: list[str] = field(default_factory=list)
    timings_ms: dict[str, float] = field(default_factory=dict)
    camera: dict[str, Any] = field(default_factory=dict)  # report.json's "camera" (JSON-ready)
    fit: dict[str, Any] = field(default_factory=dict)  # report.json's "fit" (JSON-ready)

    @property
    def side_face(self) -> SideFace:
        """Where the second face lies: the spec's choice, or what its points say (as planned)."""
        assert self.spec.points is not None
        return resolve_side_face(self.spec.points, self.spec.side_face, two_photo=self.spec.two_photo)


@dataclass(frozen=True)
class ScanResult:
    cloud: Cloud
    report: ScanReport  # report.json (`prismcore.report.report_dict`)


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + (time.perf_counter() - start) * 1000


def _check_image(image: np.ndarray, name: str) -> None:
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 2:
        raise InputError(f"{name} image must be RGB of shape (H, W, 3), got {image.shape}")


def plan_scan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None = None, *,
              exif_focal_px: float | None = None, pooled_focal: PooledFocal | None = None,
              rough_points: bool = False, click_noise_rules: bool = True) -> ScanPlan:
    """Validate the points, locate the faces and measure the prism.

    The focal length is, in this order of trust: the spec's `focal_px`, its `camera`,
    `exif_focal_px` (read from the photo by the caller, in pixels of the decoded image),
    `pooled_focal` (fitted over the photos of one camera, `prismcore.video.pooling.pool_focal`), or
    fitted from the box itself (one photo, seven points). A camera with lens distortion has it
    removed from the images and the points first (see `prepare_images`).

    `rough_points`: the points are seeds a few px off (the point search's), not clicks: the
    refined edges' box is kept even when it sits far from them (a person's clicks win over
    edges that snapped to a printed border; a rough seed's do not).

    `click_noise_rules`: the edges' box also gives way to the clicks' when it moves them more than
    their noise explains (`fit.unless_snapped`); a joint fit of several views, which weighs each
    view's lines itself, asks for the edges without it.

    Raises
    ------
    InputError
        For a missing side photo, points outside the image, out of order or collinear, points
        that mark no second face (or not the spec's `side_face`), or a video spec (one with
        `frames`: each frame has its own spec, see `video.frame_spec`).
    """
    return _plan(spec, front, side, exif_focal_px=exif_focal_px, pooled_focal=pooled_focal,
                 rough_points=rough_points, click_noise_rules=click_noise_rules)[0]


def _plan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None, *, exif_focal_px: float | None,
          pooled_focal: PooledFocal | None, rough_points: bool, click_noise_rules: bool
          ) -> tuple[ScanPlan, list[np.ndarray]]:
    """`plan_scan`'s plan, and the images its coordinates refer to (`prepare_images`'s): `run_scan`
    scans those, not the photos undistorted a second time."""
    if spec.is_video or spec.points is None:
        raise InputError(f"{spec.image!r} is a video spec: measure each frame with the spec "
                         "prismcore.video.frames.frame_spec gives for it")
    if spec.two_photo and side is None:
        raise InputError("two-photo mode: the side image is missing")
    images = [front] + ([side] if spec.two_photo and side is not None else [])
    for name, img in zip(("front", "side"), images, strict=False):
        _check_image(img, name)
    timings: dict[str, float] = {}
    warnings: list[str] = []
    side_index = 1 if spec.two_photo else 0
    # Read from the points as clicked (before undistortion), as ScanPlan.side_face reads it.
    side_face = check_points(spec, front.shape, images[side_index].shape)
    if exif_focal_px is not None and not (math.isfinite(exif_focal_px) and exif_focal_px > 0):
        raise InputError(f"the EXIF focal length must be a positive number of pixels, got {exif_focal_px!r}")
    cameras = camera_models(spec.camera, images)
    points = spec.points
    undistorted = bool(cameras is not None and cameras[0].has_distortion)
    if undistorted:
        assert cameras is not None
        images = prepare_images(spec.camera, images)
        front = images[0]
        points = undistorted_points(spec.points, cameras, two_photo=spec.two_photo)
    work = spec.model_copy(update={"points": points})
    with _timed(timings, "refine"):
        marked, _ = marked_quads(work, side_face, front.shape, images[side_index].shape)
        quads = marked
        fits: dict[str, list[EdgeFit]] = {}
        uses: EdgeUses = {}
        if spec.method == "default":
            quads, fits, uses = refine_faces(spec, images, marked, warnings)
    with _timed(timings, "measure"):
        focal = resolve_focal(images, cameras, focal_px=spec.focal_px, principal_point=spec.principal_point,
                              exif_focal_px=exif_focal_px, pooled=pooled_focal)
        if isinstance(spec.scale, Pinhole) and focal.focal_px is None and not (
                spec.method == "default" and quads.front_complete and quads.side_complete
                and not spec.two_photo):
            raise InputError("a shooting distance needs the focal length: give focal_px, a camera, or "
                             "P6 and P7 in one photo (the focal length is then fitted)")
        dims, quads, camera = measure_faces(work, quads, marked, fits, images, focal, warnings)
        if fits and dims.perspective and not spec.two_photo and not rough_points:
            dims, quads, camera, fits, uses = unless_snapped(work, marked, fits, images, focal, warnings,
                                                              (dims, quads, camera), uses,
                                                              noise_rules=click_noise_rules)
        camera["undistorted"] = undistorted
        fit = fit_guard(spec, marked, quads, dims.perspective, warnings)
        if uses:  # per side, the refined edge or the click, and why (report.json, the overlay)
            fit["edges"] = edge_use_json(uses)
    if spec.two_photo and spec.points.p7 is None and side_height_guess(spec) is None:
        # Nothing ties the side photo's scale to the front's: it is assumed, and said so
        # (instead of the note that the height carried it across, which would read as measured).
        dims = replace(dims, notes=tuple(n for n in dims.notes if "shared height" not in n))
        warnings.append(SAME_SCALE_ASSUMED)
    if dims.unit == "px":
        warnings.append(in_pixels_warning(spec))
    for name in ("width", "height", "depth"):
        value = getattr(dims, name)
        if not (math.isfinite(value) and value > 0):  # e.g. a pose fitted behind the camera
            raise InputError(f"the points do not describe a box in front of the camera: {name} "
                             f"came out as {value:.4g} {dims.unit}; check the points and their order")
    faces = []
    for name, index, region, mark in (("front", 0, quads.front, marked.front),
                                      ("side", side_index, quads.side, marked.side)):
        seed: tuple[float, float, float] | None = None
        if spec.method == "paper":
            # The first pixel of the region, read as the median of the 3x3 pixels just inside
            # the corner: a click exactly on the corner must not seed the scan with background.
            x, y = np.rint(mark[0]).astype(int)
            patch = images[index][y + 1 : y + 4, x + 1 : x + 4].reshape(-1, 3)
            r, g, b = (float(c) for c in np.median(patch, axis=0))
            seed = (r, g, b)
        window = window_for([region, mark], images[index].shape)
        faces.append(FacePlan(name, index, region, mark, window, spec.method, seed, spec.tolerance))
    return ScanPlan(spec, (faces[0], faces[1]), dims, fits,
                    [(img.shape[1], img.shape[0]) for img in images], warnings, timings, camera, fit), images


def scan_face(image: np.ndarray, face: FacePlan, tiles: int = 1) -> FaceScan:
    """Scan one face, split into `tiles` row bands (the result does not depend on `tiles`)."""
    return merge_bands(face, [scan_band(image, face, r0, r1) for r0, r1 in row_tiles(face, tiles)])


def finish_scan(plan: ScanPlan, images: list[np.ndarray], scans: list[FaceScan]) -> ScanResult:
    """Assemble the cloud from the merged face scans and write the report."""
    dims = plan.dimensions
    face = plan.side_face
    with _timed(plan.timings_ms, "assemble"):
        front = face_points(scans[0], images[scans[0].plan.image], (dims.width, dims.height))
        size = (dims.width, dims.depth) if face == "top" else (dims.depth, dims.height)
        side = face_points(scans[1], images[scans[1].plan.image], size)
        cloud = assemble(front, side, dims.width, dims.depth, plan.spec.cloud,
                         plan.spec.max_points, side_face=face, height=dims.height)
        if plan.spec.spacing_mm is not None:
            cloud = thin_to_spacing(cloud, plan.spec.spacing_mm)
    report = build_report(plan, scans, cloud)
    report.quality = report_quality(report, plan.spec.nominal, plan.spec.tolerance_mm)
    return ScanResult(cloud, report)


def _point_loss_warning(plan: ScanPlan, scans: list[FaceScan]) -> list[str]:
    """A warning when some face's cloud lacks more than POINT_LOSS_WARN of its marked pixels:
    the figures come with a cloud full of holes (or nearly empty), and the user must be told."""
    counts = [(s.plan.name, *s.point_loss_counts) for s in scans]
    if not any(total and lost / total > POINT_LOSS_WARN for _, lost, total in counts):
        return []
    lost_all, total_all = sum(c[1] for c in counts), sum(c[2] for c in counts)
    kept = " and ".join(f"{total - lost:,} of the {name} face's {total:,}" for name, lost, total in counts)
    cause = (f"the faces' colour differs from the colour at P1 by more than the tolerance "
             f"({plan.spec.tolerance:g})" if plan.spec.method == "paper"
             else "the faces are not where the points put them")
    return [f"point loss {lost_all / total_all:.1%}: the cloud keeps {kept} marked pixels; "
            f"the points may not outline the faces, or {cause}"]


def build_report(plan: ScanPlan, scans: list[FaceScan], cloud: Cloud) -> ScanReport:
    """The report (without the writers' timings, which the caller adds, nor the verdicts)."""
    rejected = sum(s.point_loss_counts[0] for s in scans)
    marked = sum(s.point_loss_counts[1] for s in scans)
    dims = plan.dimensions
    faces = {}
    for scan in scans:
        lost, total = scan.point_loss_counts
        face = {
            "corners": np.round(scan.plan.region, 3).tolist(),
            "object_pixels": int(scan.object_mask.sum()),
            "marked_pixels": total,
            "point_loss": round(lost / total, 6) if total else 0.0,
        }
        if scan.plan.name in plan.edges:
            face["edges"] = [
                {"side": s, "fitted": f.fitted, "support": round(f.support, 3),
                 "rms_px": round(f.rms_px, 3)}
                for s, f in zip(("top", "right", "bottom", "left"), plan.edges[scan.plan.name],
                                strict=True)
            ]
        faces[scan.plan.name] = face
    return ScanReport.model_validate({
        "points": int(cloud.points.shape[0]),
        "dimensions": {"width": round(dims.width, 4), "height": round(dims.height, 4),
                       "depth": round(dims.depth, 4), "unit": dims.unit},
        "uncertainty": (None if dims.uncertainty is None else
                        dict(zip(("width", "height", "depth"),
                                 (round(u, 4) for u in dims.uncertainty), strict=True))),
        "camera": plan.camera,
        "fit": plan.fit,
        "point_loss": round(rejected / marked, 6) if marked else 0.0,
        "method": plan.spec.method,
        "side_face": plan.side_face,
        "cloud": plan.spec.cloud,
        "perspective_corrected": dims.perspective,
        "faces": faces,
        "warnings": plan.warnings + list(dims.notes) + _point_loss_warning(plan, scans),
        "timings_ms": {k: round(v, 3) for k, v in plan.timings_ms.items()},
        "images": [{"width": w, "height": h} for w, h in plan.image_sizes],
        "inputs": plan.spec.model_dump(mode="json"),
        "engine_version": __version__,
    })


def run_scan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None = None, *,
             tiles: int = 1, exif_focal_px: float | None = None,
             pooled_focal: PooledFocal | None = None) -> ScanResult:
    """Plan, scan every face in `tiles` row bands and assemble, in this process."""
    plan, images = _plan(spec, front, side, exif_focal_px=exif_focal_px, pooled_focal=pooled_focal,
                         rough_points=False, click_noise_rules=True)
    with _timed(plan.timings_ms, "scan"):
        scans = [scan_face(images[f.image], f, tiles) for f in plan.faces]
    return finish_scan(plan, images, scans)

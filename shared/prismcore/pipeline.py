"""The scan as three stages: plan (once), scan tiles (in parallel if wanted), finish (once).

``run_scan`` chains them in one process; the worker runs the same stages as separate tasks.
Images are RGB arrays (H, W, 3): uint8, or float32 in 0-255 units for 16-bit inputs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from . import __version__
from .cloud import Cloud, assemble, face_points
from .edges import EdgeFit, inward, line_through, refine_quad
from .errors import InputError
from .faces import FaceQuads, clicked_quads, paper_rectangles, validate_points, validate_quad
from .measure import Dimensions, camera_matrix, measure_affine, measure_perspective
from .perspective import FaceEvidence
from .scan import FacePlan, FaceScan, merge_bands, row_tiles, scan_band, window_for
from .spec import MmPerPx, Pinhole, ScanSpec

__all__ = ["ScanPlan", "ScanResult", "finish_scan", "plan_scan", "run_scan", "scan_face"]

SEARCH_PX = 10.0  # how far from a clicked side its true edge may be
SAME_SCALE_ASSUMED = ("two photos, no P7 and a scale for only one of them: the other is taken to be "
                      "at the same scale (shot from the same distance), and the dimensions it gives "
                      "rest on that; mark P7, or give each photo its scale, to measure them")


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


@dataclass(frozen=True)
class ScanResult:
    cloud: Cloud
    report: dict


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + (time.perf_counter() - start) * 1000


def _check_image(image: np.ndarray, name: str) -> None:
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 2:
        raise InputError(f"{name} image must be RGB of shape (H, W, 3), got {image.shape}")


def _refine(spec: ScanSpec, images: list[np.ndarray], clicked: FaceQuads, warnings: list[str]):
    """Edge-fit both faces; the single-photo side face reuses the front's right edge."""
    def search(quad: np.ndarray) -> float:
        sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
        return float(min(SEARCH_PX, 0.3 * sides.min()))

    fits: dict[str, list[EdgeFit]] = {}
    refined = {}
    jobs = [("front", 0, clicked.front), ("side", 1 if spec.two_photo else 0, clicked.side)]
    for name, index, quad in jobs:
        r = search(quad)
        known = extra = None
        if not spec.two_photo:
            if name == "side":
                known = {3: fits["front"][1]}
            else:
                # In one photo the side face lies beyond the front's right edge: the edge must
                # not be taken from the side face's far (right) side.
                far = inward(line_through(clicked.side[1], clicked.side[2]), clicked.side[0])
                extra = {1: ((far, 0.5 * float(far[:2] @ clicked.side[0] + far[2])),)}
        corners, face_fits = refine_quad(images[index], quad, search_px=r, known=known,
                                         extra_bounds=extra)
        moved = np.linalg.norm(corners - quad, axis=1).max() if np.isfinite(corners).all() else np.inf
        try:
            if moved > 3 * r + 4:
                raise InputError("refined corners moved too far")
            validate_quad(corners, f"refined {name} face", images[index].shape)
        except InputError:
            warnings.append(f"{name} face: edges not found near the clicks; clicked corners used")
            corners = quad
        if not all(f.fitted for f in face_fits):
            missing = [s for s, f in zip(("top", "right", "bottom", "left"), face_fits,
                                         strict=True) if not f.fitted]
            warnings.append(f"{name} face: no clear edge along the {', '.join(missing)} side; "
                            "the click was used there")
        fits[name], refined[name] = face_fits, corners
    return FaceQuads(refined["front"], refined["side"], clicked.front_complete,
                     clicked.side_complete), fits


def _side_height_guess(spec: ScanSpec) -> float | None:
    """Two photos without p7: the front's height in side-photo pixels, when the scales tell it."""
    if not spec.two_photo or spec.points.p7 is not None:
        return None
    front_px = float(np.hypot(*np.subtract(spec.points.p3, spec.points.p2)))
    scale = spec.scale
    if isinstance(scale, MmPerPx) and scale.side:
        return front_px * scale.front / scale.side
    if isinstance(scale, Pinhole) and scale.side_distance_mm:
        return front_px * scale.distance_mm / scale.side_distance_mm
    return None


def _measure(spec: ScanSpec, quads: FaceQuads, marked: FaceQuads, fits: dict[str, list[EdgeFit]],
             images: list[np.ndarray], warnings: list[str]) -> tuple[Dimensions, FaceQuads]:
    """The prism's dimensions, and the face quads to scan (the fitted model's, in perspective)."""
    complete = quads.front_complete and quads.side_complete
    if spec.method == "default" and spec.focal_px is not None and complete:
        Ks = [camera_matrix(spec.focal_px, spec.principal_point or
                            ((img.shape[1] - 1) / 2, (img.shape[0] - 1) / 2)) for img in images]
        evidence = [FaceEvidence(getattr(quads, n), getattr(marked, n),
                                 tuple(f.line if f.fitted else None for f in fits[n]))
                    for n in ("front", "side")]
        dims, front, side = measure_perspective(*evidence, spec.scale, K_front=Ks[0],
                                                K_side=Ks[-1], two_photo=spec.two_photo)
        return dims, FaceQuads(front, side, True, True)
    if spec.method == "default" and spec.focal_px is not None:
        warnings.append("perspective not corrected: it needs p6 and p7 besides the focal length")
    dims = measure_affine(quads.front, quads.side, spec.scale, focal_px=spec.focal_px,
                          two_photo=spec.two_photo)
    return dims, quads


def plan_scan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None = None) -> ScanPlan:
    """Validate the points, locate the faces and measure the prism.

    Raises
    ------
    InputError
        For a missing side photo, points outside the image, out of order or collinear, or a
        video spec (one with `frames`: each frame has its own spec, see `video.frame_spec`).
    """
    if spec.is_video or spec.points is None:
        raise InputError(f"{spec.image!r} is a video spec: measure each frame with the spec "
                         "prismcore.video.frame_spec gives for it")
    if spec.two_photo and side is None:
        raise InputError("two-photo mode: the side image is missing")
    images = [front] + ([side] if spec.two_photo and side is not None else [])
    for name, img in zip(("front", "side"), images, strict=False):
        _check_image(img, name)
    timings: dict[str, float] = {}
    warnings: list[str] = []
    side_index = 1 if spec.two_photo else 0
    validate_points(spec.points, front.shape, images[side_index].shape)
    with _timed(timings, "refine"):
        if spec.method == "paper":
            quads = paper_rectangles(spec.points, two_photo=spec.two_photo)
            marked = quads
        else:
            marked = clicked_quads(spec.points, two_photo=spec.two_photo,
                                   side_height_px=_side_height_guess(spec))
        validate_quad(marked.front, "front face", front.shape)
        validate_quad(marked.side, "side face", images[side_index].shape)
        fits: dict[str, list[EdgeFit]] = {}
        if spec.method == "default":
            quads, fits = _refine(spec, images, marked, warnings)
    with _timed(timings, "measure"):
        dims, quads = _measure(spec, quads, marked, fits, images, warnings)
    if spec.two_photo and spec.points.p7 is None and _side_height_guess(spec) is None:
        # Nothing ties the side photo's scale to the front's: it is assumed, and said so
        # (instead of the note that the height carried it across, which would read as measured).
        dims = replace(dims, notes=tuple(n for n in dims.notes if "shared height" not in n))
        warnings.append(SAME_SCALE_ASSUMED)
    for name in ("width", "height", "depth"):
        value = getattr(dims, name)
        if not (math.isfinite(value) and value > 0):  # e.g. a pose fitted behind the camera
            raise InputError(f"the points do not describe a box in front of the camera: {name} "
                             f"came out as {value:.4g} {dims.unit}; check the points and their order")
    faces = []
    for name, index, region, mark in (("front", 0, quads.front, marked.front),
                                      ("side", side_index, quads.side, marked.side)):
        seed = None
        if spec.method == "paper":
            # The first pixel of the region, read as the median of the 3x3 pixels just inside
            # the corner: a click exactly on the corner must not seed the scan with background.
            x, y = np.rint(mark[0]).astype(int)
            patch = images[index][y + 1 : y + 4, x + 1 : x + 4].reshape(-1, 3)
            seed = tuple(float(c) for c in np.median(patch, axis=0))
        window = window_for([region, mark], images[index].shape)
        faces.append(FacePlan(name, index, region, mark, window, spec.method, seed, spec.tolerance))
    return ScanPlan(spec, (faces[0], faces[1]), dims, fits,
                    [(img.shape[1], img.shape[0]) for img in images], warnings, timings)


def scan_face(image: np.ndarray, face: FacePlan, tiles: int = 1) -> FaceScan:
    """Scan one face, split into `tiles` row bands (the result does not depend on `tiles`)."""
    return merge_bands(face, [scan_band(image, face, r0, r1) for r0, r1 in row_tiles(face, tiles)])


def finish_scan(plan: ScanPlan, images: list[np.ndarray], scans: list[FaceScan]) -> ScanResult:
    """Assemble the cloud from the merged face scans and write the report."""
    dims = plan.dimensions
    with _timed(plan.timings_ms, "assemble"):
        front = face_points(scans[0], images[scans[0].plan.image], (dims.width, dims.height))
        side = face_points(scans[1], images[scans[1].plan.image], (dims.depth, dims.height))
        cloud = assemble(front, side, dims.width, dims.depth, plan.spec.cloud,
                         plan.spec.max_points)
    return ScanResult(cloud, build_report(plan, scans, cloud))


def build_report(plan: ScanPlan, scans: list[FaceScan], cloud: Cloud) -> dict:
    """The report.json content (without the writers' timings, which the caller adds)."""
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
    return {
        "points": int(cloud.points.shape[0]),
        "dimensions": {"width": round(dims.width, 4), "height": round(dims.height, 4),
                       "depth": round(dims.depth, 4), "unit": dims.unit},
        "point_loss": round(rejected / marked, 6) if marked else 0.0,
        "method": plan.spec.method,
        "cloud": plan.spec.cloud,
        "perspective_corrected": dims.perspective,
        "faces": faces,
        "warnings": plan.warnings + list(dims.notes),
        "timings_ms": {k: round(v, 3) for k, v in plan.timings_ms.items()},
        "images": [{"width": w, "height": h} for w, h in plan.image_sizes],
        "inputs": plan.spec.model_dump(mode="json"),
        "engine_version": __version__,
    }


def run_scan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None = None, *,
             tiles: int = 1) -> ScanResult:
    """Plan, scan every face in `tiles` row bands and assemble, in this process."""
    plan = plan_scan(spec, front, side)
    images = [front] + ([side] if spec.two_photo and side is not None else [])
    with _timed(plan.timings_ms, "scan"):
        scans = [scan_face(images[f.image], f, tiles) for f in plan.faces]
    return finish_scan(plan, images, scans)

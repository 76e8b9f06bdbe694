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
from typing import TYPE_CHECKING, Any

import numpy as np

from prismcore._version import __version__
from prismcore.errors import InputError
from prismcore.geometry.edges import Bound, EdgeFit, inward, line_through, refine_quad
from prismcore.geometry.faces import (
    FaceQuads,
    Labels,
    SideFace,
    clicked_quads,
    paper_rectangles,
    quad_labels,
    resolve_side_face,
    shared_edges,
    validate_points,
    validate_quad,
)
from prismcore.geometry.perspective import NOISE_CLICK_PX, FaceEvidence
from prismcore.quality.verdicts import quality_from_report
from prismcore.scan.cloud import Cloud, assemble, face_points
from prismcore.scan.colour_scan import FacePlan, FaceScan, merge_bands, row_tiles, scan_band, window_for
from prismcore.scan.measure import (
    Dimensions,
    camera_matrix,
    measure_affine,
    measure_box,
    measure_perspective,
    obliqueness,
    square_on_cost,
)
from prismcore.scan.spacing import thin_to_spacing
from prismcore.spec import MmPerPx, Pinhole, ReferencePoints, ScanSpec

if TYPE_CHECKING:
    from prismcore.camera import CameraModel

__all__ = ["PooledFocal", "ScanPlan", "ScanResult", "finish_scan", "plan_scan", "prepare_images", "run_scan",
           "scan_face"]

FIT_WARN_PX = 3.0  # a click this far from the fitted model's corner is worth a look
FIT_FAIL_PX = 25.0  # ... and this far (or 5 % of the face's size) means the fit is wrong
FIT_FAIL_FRACTION = 0.05
SNAP_SUSPECT_RMS_PX = 5.0  # a fit to the refined edges this far (RMS) from the clicks is suspect...
SNAP_CLICKS_BETTER = 3.0  # ... and is replaced when the clicks alone fit a box this many times closer
FOCAL_MAX_REL_STD = 0.25  # a fitted focal less sure than this is "not determined"
OBLIQUE_WARN = 0.01  # warn when the square-on model costs more than 1 % on some dimension
POINT_LOSS_WARN = 0.2  # warn when a face's cloud lacks more than this share of its marked pixels
_POINT_ROLES = {
    "p1": "the front face's upper-left corner",
    "p2": "the front face's upper-right corner",
    "p3": "the front face's lower-right corner",
    "p4": "the side face's upper-left corner",
    "p5": "the side face's upper-right corner",
    "p6": "the front face's lower-left corner",
    "p7": "the side face's lower-right corner",
}
_SECOND_FACE_ROLES = {
    "left": {"p4": "the corner P1 marks (where the left side face starts)",
             "p5": "the left side face's far upper corner",
             "p7": "the left side face's far lower corner"},
    "top": {"p4": "the corner P1 marks (where the top face starts)",
            "p5": "the top face's far corner above P1",
            "p7": "the top face's far corner above P2"},
}

SEARCH_PX = 10.0  # how far from a clicked side its true edge may be
SAME_SCALE_ASSUMED = ("two photos, no P7 and a scale for only one of them: the other is taken to be "
                      "at the same scale (shot from the same distance), and the dimensions it gives "
                      "rest on that; mark P7, or give each photo its scale, to measure them")


@dataclass(frozen=True)
class PooledFocal:
    """The pooled focal length and how it was reached.

    focal_px : float
        The inverse-variance weighted mean of the estimates kept, px.
    std_px : float
        Its standard error, px, widened by the scatter of the estimates when they disagree more
        than their own errors say (Birge ratio).
    used : tuple of int
        Indices of the estimates kept; the others disagreed with the median by more than
        3 sigma (their own error combined with the estimates' robust scatter).
    """

    focal_px: float
    std_px: float
    used: tuple[int, ...]


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
    report: dict[str, Any]


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + (time.perf_counter() - start) * 1000


def _check_image(image: np.ndarray, name: str) -> None:
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 2:
        raise InputError(f"{name} image must be RGB of shape (H, W, 3), got {image.shape}")


def _refine(
    spec: ScanSpec, images: list[np.ndarray], clicked: FaceQuads, warnings: list[str]
) -> tuple[FaceQuads, dict[str, list[EdgeFit]]]:
    """Edge-fit both faces; the single-photo side face reuses the front's edge it shares."""
    def search(quad: np.ndarray) -> float:
        sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
        return float(min(SEARCH_PX, 0.3 * sides.min()))

    fits: dict[str, list[EdgeFit]] = {}
    refined = {}
    jobs = [("front", 0, clicked.front), ("side", 1 if spec.two_photo else 0, clicked.side)]
    for name, index, quad in jobs:
        r = search(quad)
        known: dict[int, EdgeFit] | None = None
        extra: dict[int, tuple[Bound, ...]] | None = None
        if not spec.two_photo:
            front_edge, side_edge = shared_edges(clicked.side_face)
            if name == "side":
                known = {side_edge: fits["front"][front_edge]}
            else:
                # In one photo the side face lies beyond the front's shared edge: that edge must
                # not be taken from the side face's far side.
                o, ref = (side_edge + 2) % 4, clicked.side[(side_edge + 1) % 4]
                far = inward(line_through(clicked.side[o], clicked.side[(o + 1) % 4]), ref)
                extra = {front_edge: ((far, 0.5 * float(far[:2] @ ref + far[2])),)}
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
                     clicked.side_complete, clicked.side_face), fits


def _side_height_guess(spec: ScanSpec) -> float | None:
    """Two photos without p7: the front's height in side-photo pixels, when the scales tell it."""
    if not spec.two_photo:
        return None
    assert spec.points is not None  # a photo spec carries its clicks
    if spec.points.p7 is not None:
        return None
    front_px = float(np.hypot(*np.subtract(spec.points.p3, spec.points.p2)))
    scale = spec.scale
    if isinstance(scale, MmPerPx) and scale.side:
        return front_px * scale.front / scale.side
    if isinstance(scale, Pinhole) and scale.side_distance_mm:
        return front_px * scale.distance_mm / scale.side_distance_mm
    return None


@dataclass(frozen=True)
class _Focal:
    """The focal length and principal point the fit starts from, and where they came from."""

    focal_px: float | None
    source: str  # given | camera | exif | pooled | none (fitted is decided by the fit)
    principal: list[tuple[float, float]]  # per image
    extra: dict[str, Any] = field(default_factory=dict)  # report fields of the source (a pooled std, ...)


PRINCIPAL_MARGIN = 0.5
"""How far outside the photo a principal point may lie, as a fraction of the photo's size: a
shift lens moves it a quarter of the frame at most; far outside, the perspective fit's start is
so far off that it wanders (1e6 px ran for minutes, 1e9 asked for 48 GiB)."""


def _check_principal(centre: tuple[float, float], width: int, height: int, what: str) -> None:
    """Refuse a principal point (x, y) px far outside a `width` x `height` photo."""
    x, y = centre
    mx, my = PRINCIPAL_MARGIN * width, PRINCIPAL_MARGIN * height
    if not (-mx <= x <= width - 1 + mx and -my <= y <= height - 1 + my):
        raise InputError(f"{what} ({x:g}, {y:g}) px lies far outside the {width}x{height} px photo: "
                         "it is where the lens axis meets the image, near its centre "
                         f"(here about ({(width - 1) / 2:g}, {(height - 1) / 2:g}))")


def _resolve_focal(spec: ScanSpec, images: list[np.ndarray], cameras: list[CameraModel] | None,
                   exif_focal_px: float | None, pooled: PooledFocal | None = None) -> _Focal:
    """Order of trust: given > camera profile > EXIF > pooled over the camera's photos >
    (fitted later)."""
    centres = [((img.shape[1] - 1) / 2, (img.shape[0] - 1) / 2) for img in images]
    if cameras is not None:
        centres = [(c.cx, c.cy) for c in cameras]
    if spec.principal_point is not None:
        centres = [tuple(spec.principal_point)] * len(images)  # type: ignore[list-item]
    for img, centre in zip(images, centres, strict=True):
        _check_principal(centre, img.shape[1], img.shape[0], "principal_point" if spec.principal_point
                         is not None else "the camera model's cx, cy")
    if spec.focal_px is not None:
        return _Focal(float(spec.focal_px), "given", centres)
    if cameras is not None:
        return _Focal(float(np.sqrt(cameras[0].fx * cameras[0].fy)), "camera", centres)
    if exif_focal_px is not None:
        return _Focal(float(exif_focal_px), "exif", centres)
    if pooled is not None:
        return _Focal(float(pooled.focal_px), "pooled", centres,
                      {"focal_std_px": round(pooled.std_px, 3), "pooled_photos": len(pooled.used)})
    return _Focal(None, "none", centres)


def _oblique_warning(spec: ScanSpec, quads: FaceQuads, dims: Dimensions, warnings: list[str]) -> None:
    """Say how oblique a single photo measured with the square-on model is, and what it costs."""
    view = obliqueness(quads.front, quads.side, quads.side_face)
    if view is None:
        return
    cost = square_on_cost(view, spec.scale)
    if cost.max() <= OBLIQUE_WARN:
        return
    worst = ("width", "height", "depth")[int(np.argmax(cost))]
    model = "the paper's method" if spec.method == "paper" else "the square-on model"
    fix = "" if spec.method == "paper" else "; mark P6 and P7 to have perspective corrected"
    second = "top face" if quads.side_face == "top" else "side face"
    warnings.append(f"oblique photo measured with {model}: the front face is seen {view.front_deg:.0f}° "
                    f"and the {second} {view.side_deg:.0f}° off square-on, which costs about "
                    f"{cost.max():.0%} on the {worst}{fix}")


def _measure(spec: ScanSpec, quads: FaceQuads, marked: FaceQuads, fits: dict[str, list[EdgeFit]],
             images: list[np.ndarray], focal: _Focal, warnings: list[str]
             ) -> tuple[Dimensions, FaceQuads, dict[str, Any]]:
    """The prism's dimensions, the face quads to scan (the fitted model's, in perspective) and
    the report's "camera" fields."""
    complete = quads.front_complete and quads.side_complete
    face = quads.side_face
    camera = {"focal_px": focal.focal_px, "focal_source": focal.source,
              "principal_point": [round(float(v), 3) for v in focal.principal[0]], **focal.extra}
    if spec.method == "default" and complete and (focal.focal_px is not None or not spec.two_photo):
        evidence = [FaceEvidence(getattr(quads, n), getattr(marked, n),
                                 tuple(f.line if f.fitted else None for f in fits[n]),
                                 tuple(f.points if f.fitted else None for f in fits[n]))
                    for n in ("front", "side")]
        if spec.two_photo:
            assert focal.focal_px is not None
            Ks = [camera_matrix(focal.focal_px, c) for c in focal.principal]
            dims, front, side = measure_perspective(evidence[0], evidence[1], spec.scale, K_front=Ks[0],
                                                    K_side=Ks[-1], two_photo=True)
            return dims, FaceQuads(front, side, True, True), camera
        free = focal.focal_px is None
        K = camera_matrix(focal.focal_px or 1.0, focal.principal[0])
        dims, fit = measure_box(evidence[0], evidence[1], spec.scale, K=K, free_focal=free, side_face=face,
                                lens_known=focal.source == "camera", image=images[0])
        if free:
            assert fit.focal_std_px is not None
            camera.update(focal_px=round(fit.focal_px, 3), focal_source="fitted",
                          focal_std_px=round(fit.focal_std_px, 3))
            if not fit.focal_std_px < FOCAL_MAX_REL_STD * fit.focal_px:
                note = (f"the view shows too little perspective to fit the focal length "
                        f"({fit.focal_px:.0f} ± {fit.focal_std_px:.0f} px): measured as a nearly "
                        "square-on (weak-perspective) view; give the focal length or a camera to be sure")
                dims = replace(dims, notes=(*dims.notes, note))
        return dims, FaceQuads(fit.front_quad, fit.side_quad, True, True, face), camera
    if spec.method == "default" and focal.source != "none":
        warnings.append("perspective not corrected: it needs p6 and p7 besides the focal length")
    camera["focal_source"] = "none" if focal.source == "none" else focal.source
    # The paper's rectangles are axis-aligned by design: the view is read from the clicks.
    assert spec.points is not None
    shape = clicked_quads(spec.points, two_photo=False, side_face=face) if spec.method == "paper" else quads
    view = None if spec.two_photo else obliqueness(shape.front, shape.side, face)
    # A Pinhole scale's mm-per-pixel reads the focal length (given, camera or EXIF).
    dims = measure_affine(quads.front, quads.side, spec.scale, focal_px=focal.focal_px,
                          two_photo=spec.two_photo, view=view,
                          corner_noise_px=NOISE_CLICK_PX,
                          clicked=(marked.front, marked.side) if fits else None, side_face=face)
    if not spec.two_photo:
        _oblique_warning(spec, shape, dims, warnings)
    return dims, quads, camera


def _click_rms(marked: FaceQuads, model: FaceQuads) -> float:
    """RMS distance (px) between the clicked points and the model's corners they mark."""
    d = [np.linalg.norm(corner - click)
         for face in ("front", "side")
         for label, click, corner in zip(quad_labels(marked)[face == "side"], getattr(marked, face),
                                         getattr(model, face), strict=True) if label is not None]
    return float(np.sqrt(np.mean(np.square(d)))) if d else 0.0


def _unless_snapped(spec: ScanSpec, marked: FaceQuads, fits: dict[str, list[EdgeFit]],
                    images: list[np.ndarray], focal: _Focal, warnings: list[str],
                    refined: tuple[Dimensions, FaceQuads, dict[str, Any]],
                    ) -> tuple[Dimensions, FaceQuads, dict[str, Any], dict[str, list[EdgeFit]]]:
    """The box fitted to the refined edges, unless the edges snapped to something else.

    Edge refinement takes the consensus line near each clicked side; on a real box that can be a
    printed border, a lid's seam or the background past a corner (a real video: 10-20 px off).
    Its box then sits far from the clicks while the clicks alone fit a box closely. A fit
    farther than click noise explains (SNAP_SUSPECT_RMS_PX) is compared with the clicks' own
    fit, and the clicks win when they fit SNAP_CLICKS_BETTER times closer.
    """
    dims, quads, camera = refined
    rms = _click_rms(marked, quads)
    if not rms > SNAP_SUSPECT_RMS_PX:
        return dims, quads, camera, fits
    plain = {n: [EdgeFit(line_through(q[i], q[(i + 1) % 4]), 0.0, 0.0, False) for i in range(4)]
             for n, q in (("front", marked.front), ("side", marked.side))}
    scratch: list[str] = []
    alt = _measure(spec, marked, marked, plain, images, focal, scratch)
    alt_rms = _click_rms(marked, alt[1])
    if not alt_rms * SNAP_CLICKS_BETTER < rms:
        return dims, quads, camera, fits
    warnings.extend(scratch)
    warnings.append(f"the refined edges fit a box {rms:.1f} px (RMS) from the clicks, the clicks "
                    f"alone one {alt_rms:.1f} px: the edges found were not the box's (printed "
                    "borders or background?), so the clicks were used")
    return *alt, plain


def _guard(spec: ScanSpec, marked: FaceQuads, model: FaceQuads, perspective: bool,
           warnings: list[str]) -> dict[str, Any]:
    """Distances between each click and the model's corner; warn, or refuse a clearly wrong fit.

    Only a fitted pinhole model is refused: the square-on model's corners are the refined
    clicks themselves, and the paper's rectangles ignore part of the clicks by design.
    """
    residuals: dict[str, float] = {}
    limits: dict[str, float] = {}
    for face in ("front", "side"):
        clicks, corners = getattr(marked, face), getattr(model, face)
        size = float(np.linalg.norm(clicks[2] - clicks[0]))
        for label, click, corner in zip(quad_labels(marked)[face == "side"], clicks, corners,
                                        strict=True):
            if label is None:
                continue
            residuals[label] = float(np.linalg.norm(corner - click))
            limits[label] = max(FIT_FAIL_PX, FIT_FAIL_FRACTION * size)
    order = sorted(residuals)
    rms = float(np.sqrt(np.mean([residuals[n] ** 2 for n in order]))) if order else 0.0
    if spec.method == "default":
        worst = max(order, key=lambda n: residuals[n] / limits[n])
        if perspective and residuals[worst] > limits[worst]:
            role = _SECOND_FACE_ROLES.get(marked.side_face, {}).get(worst, _POINT_ROLES[worst])
            raise InputError(f"the fitted box sits {residuals[worst]:.0f} px from {worst.upper()}: "
                             f"check that {worst.upper()} is {role}")
        far = [n for n in order if residuals[n] > FIT_WARN_PX]
        if far:
            what = "fitted box's corners" if perspective else "refined face corners"
            listed = ", ".join(f"{n.upper()} ({residuals[n]:.1f} px)" for n in far)
            warnings.append(f"the {what} lie more than {FIT_WARN_PX:g} px from {listed}: "
                            "check those clicks")
    return {"rms_px": round(rms, 3), "point_residuals_px": {n: round(residuals[n], 3) for n in order}}


def _undistorted_points(spec: ScanSpec, cameras: list[CameraModel]) -> ReferencePoints:
    from prismcore.camera import undistort_points

    assert spec.points is not None
    moved = {}
    for name, xy in spec.points.as_dict().items():
        cam = cameras[1 if spec.two_photo and name in ("p4", "p5", "p7") else 0]
        moved[name] = tuple(float(v) for v in undistort_points(np.array([xy]), cam)[0])
    return ReferencePoints.model_validate(moved)


def _cameras(spec: ScanSpec, images: list[np.ndarray]) -> list[CameraModel] | None:
    """The spec's camera model for each image's size, or None."""
    if spec.camera is None:
        return None
    return [spec.camera.for_size(img.shape[1], img.shape[0]) for img in images]


def prepare_images(spec: ScanSpec, images: list[np.ndarray]) -> list[np.ndarray]:
    """The images the plan's coordinates refer to: undistorted when the spec's camera has lens
    distortion, else the images themselves. Scan the tiles and finish on these.

    images : list of (H, W, 3) RGB arrays, front first.
    """
    cameras = _cameras(spec, images)
    if cameras is None or not cameras[0].has_distortion:
        return images
    from prismcore.camera import undistort_image

    return [undistort_image(img, cam) for img, cam in zip(images, cameras, strict=True)]


def plan_scan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None = None, *,
              exif_focal_px: float | None = None, pooled_focal: PooledFocal | None = None,
              rough_points: bool = False) -> ScanPlan:
    """Validate the points, locate the faces and measure the prism.

    The focal length is, in this order of trust: the spec's `focal_px`, its `camera`,
    `exif_focal_px` (read from the photo by the caller, in pixels of the decoded image),
    `pooled_focal` (fitted over the photos of one camera, `prismcore.video.pooling.pool_focal`), or
    fitted from the box itself (one photo, seven points). A camera with lens distortion has it
    removed from the images and the points first (see `prepare_images`).

    `rough_points`: the points are seeds a few px off (the point search's), not clicks: the
    refined edges' box is kept even when it sits far from them (a person's clicks win over
    edges that snapped to a printed border; a rough seed's do not).

    Raises
    ------
    InputError
        For a missing side photo, points outside the image, out of order or collinear, points
        that mark no second face (or not the spec's `side_face`), or a video spec (one with
        `frames`: each frame has its own spec, see `video.frame_spec`).
    """
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
    validate_points(spec.points, front.shape, images[side_index].shape)
    # The front alone first: a bad front says so, rather than that no second face can be read.
    if spec.method == "paper":
        validate_quad(paper_rectangles(spec.points).front, "front face", front.shape)
    else:
        front_only = clicked_quads(spec.points, two_photo=spec.two_photo)
        validate_quad(front_only.front, "front face", front.shape, labels=quad_labels(front_only)[0])
    # Read from the points as clicked (before undistortion), as ScanPlan.side_face reads it.
    side_face = resolve_side_face(spec.points, spec.side_face, two_photo=spec.two_photo)
    if exif_focal_px is not None and not (math.isfinite(exif_focal_px) and exif_focal_px > 0):
        raise InputError(f"the EXIF focal length must be a positive number of pixels, got {exif_focal_px!r}")
    cameras = _cameras(spec, images)
    points = spec.points
    undistorted = bool(cameras is not None and cameras[0].has_distortion)
    if undistorted:
        assert cameras is not None
        images = prepare_images(spec, images)
        front = images[0]
        points = _undistorted_points(spec, cameras)
    work = spec.model_copy(update={"points": points})
    with _timed(timings, "refine"):
        if spec.method == "paper":
            quads = paper_rectangles(points, two_photo=spec.two_photo, side_face=side_face)
            marked = quads
            labels: tuple[Labels | None, Labels | None] = (None, None)
        else:
            marked = clicked_quads(points, two_photo=spec.two_photo,
                                   side_height_px=_side_height_guess(work), side_face=side_face)
            labels = quad_labels(marked)
        validate_quad(marked.front, "front face", front.shape, labels=labels[0])
        validate_quad(marked.side, "top face" if side_face == "top" else "side face",
                      images[side_index].shape, labels=labels[1])
        fits: dict[str, list[EdgeFit]] = {}
        if spec.method == "default":
            quads, fits = _refine(spec, images, marked, warnings)
    with _timed(timings, "measure"):
        focal = _resolve_focal(spec, images, cameras, exif_focal_px, pooled_focal)
        if isinstance(spec.scale, Pinhole) and focal.focal_px is None and not (
                spec.method == "default" and quads.front_complete and quads.side_complete
                and not spec.two_photo):
            raise InputError("a shooting distance needs the focal length: give focal_px, a camera, or "
                             "P6 and P7 in one photo (the focal length is then fitted)")
        dims, quads, camera = _measure(work, quads, marked, fits, images, focal, warnings)
        if fits and dims.perspective and not spec.two_photo and not rough_points:
            dims, quads, camera, fits = _unless_snapped(work, marked, fits, images, focal, warnings,
                                                        (dims, quads, camera))
        camera["undistorted"] = undistorted
        fit = _guard(spec, marked, quads, dims.perspective, warnings)
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
                    [(img.shape[1], img.shape[0]) for img in images], warnings, timings, camera, fit)


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
    report["quality"] = quality_from_report(report, plan.spec.nominal, plan.spec.tolerance_mm)
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


def build_report(plan: ScanPlan, scans: list[FaceScan], cloud: Cloud) -> dict[str, Any]:
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
    }


def run_scan(spec: ScanSpec, front: np.ndarray, side: np.ndarray | None = None, *,
             tiles: int = 1, exif_focal_px: float | None = None,
             pooled_focal: PooledFocal | None = None) -> ScanResult:
    """Plan, scan every face in `tiles` row bands and assemble, in this process."""
    plan = plan_scan(spec, front, side, exif_focal_px=exif_focal_px, pooled_focal=pooled_focal)
    images = prepare_images(spec, [front] + ([side] if spec.two_photo and side is not None else []))
    with _timed(plan.timings_ms, "scan"):
        scans = [scan_face(images[f.image], f, tiles) for f in plan.faces]
    return finish_scan(plan, images, scans)

"""A part measured on a station: re-register, segment, fit the box, and say how sure it is.

The seven reference points are derived from the fitted box, so the cloud, the overlay and the
other outputs are made from the photo as for clicked points.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from prismcore.camera import CameraModel
from prismcore.errors import InputError, PartRefusedError
from prismcore.geometry.rounding import RESOLVED_PX
from prismcore.station.boxfit import _FACES, OutlineFit, fit_outline_box, project, visible_faces
from prismcore.station.calibrate import Station
from prismcore.station.edges import fold_distance
from prismcore.station.hidden_sides import evidence_enough, read_hidden_sides, widened
from prismcore.station.registration import Registration, register
from prismcore.station.rounding import edge_radius
from prismcore.station.segment import Silhouette, segment_part
from prismcore.station.undistort import undistorter

__all__ = ["MAX_RESIDUAL_PX", "StationMeasurement", "measure_on_station", "reference_points"]

MAX_RESIDUAL_PX = 3.0  # the outline farther than this (RMS) from any box resting flat: refused
WARN_RESIDUAL_PX = 1.5
_WARN_RELATIVE_SIGMA = 0.02  # a dimension's 1 sigma over this share of it is warned: 5 % is 2.5 sigma
_SMALL_SPAN_PX = 60.0  # a side shorter than this in the photo: its size there is the cause
_SYSTEMATIC_PX = 0.6  # the outline's placement, px, common to a whole side
_WARN_MISSING = 0.08
_WARN_WEAK = 0.15
_TOP_ONLY_SIGMA = 0.05  # relative: a footprint side read on the top face alone
_SIDE_SEEN = 0.15
_MIN_SIDE_PX = 4.0  # a fitted side shorter than this in the photo is no side
_RADIUS_SHARE = 1.0  # a side's error per mm of error in the rounding's radius
_HIDDEN_SHARE = 0.6  # a side's shortfall per mm of a rounding the fit did not know of (renders: 0.45-0.65)
_HIDDEN_MAX_MM = 3.0  # the largest rounding taken to hide below the folds' resolution


def _sides_seen(corners: np.ndarray, image_pts: np.ndarray, camera_centre: np.ndarray) -> int:
    """How many side faces the camera sees at _SIDE_SEEN of the largest one's area or more."""
    areas = [area for name, (_, area) in visible_faces(corners, camera_centre, image_pts).items()
             if name != "top"]
    return sum(a >= _SIDE_SEEN * max(areas) for a in areas) if areas else 0


_PLATES: dict[tuple[str, str], np.ndarray] = {}
_PLATE_SHA1: list[tuple[str, str]] = []  # (a plate's text, its SHA-1): the last station's


def _plate_sha1(plate_png: str) -> str:
    """The SHA-1 of a station's plate, hashed once per plate (the same text object again is known)."""
    for text, digest in _PLATE_SHA1:
        if text is plate_png:
            return digest
    digest = hashlib.sha1(plate_png.encode("ascii")).hexdigest()
    _PLATE_SHA1[:] = [(plate_png, digest)]
    return digest


def _undistorted_plate(station: Station) -> np.ndarray | None:
    """The station's plate decoded and undistorted once for a batch of photos (the last station's
    kept: a worker measures one station's photos in a row), keyed on the camera and the plate's
    content."""
    if station.plate_png is None:
        return None
    key = (station.camera.model_dump_json(), _plate_sha1(station.plate_png))
    kept = _PLATES.get(key)  # read once, as undistorter's cache (threads may clear it meanwhile)
    if kept is None:
        plate = station.plate()
        assert plate is not None
        kept = undistorter(station.camera).image(plate)
        _PLATES.clear()
        _PLATES[key] = kept
    return kept


def _corner_at(point: np.ndarray, image_pts: np.ndarray) -> int:
    """The corner index whose photo pixel is `point`."""
    return int(np.argmin(np.linalg.norm(image_pts - point, axis=1)))


@dataclass
class StationMeasurement:
    """What the station measured of the part.

    dimensions : width >= depth (the footprint's sides) and height (perpendicular to the
    support), mm. uncertainty : their one-sigma, mm. position_mm : the footprint's centre in the
    station's frame. yaw_deg : the footprint's longer side against the frame's x axis.
    points : (7, 2) reference points in the photo as taken (P1..P7), side_face : their second face.
    top_only : "width" or "depth" where one side face only was seen and that footprint side was
    read on the top face alone (its sigma widened, a warning given); None when two were seen.
    """

    dimensions: dict[str, float]
    uncertainty: dict[str, float]
    position_mm: tuple[float, float]
    yaw_deg: float
    residual_px: float
    contrast: float
    registration: Registration
    fit: OutlineFit
    points: np.ndarray
    side_face: str
    warnings: list[str] = field(default_factory=list)
    timings_ms: dict[str, float] = field(default_factory=dict)
    cpu_ms: dict[str, float] = field(default_factory=dict)  # each stage's CPU time (this thread's)
    camera: CameraModel | None = None  # the camera measured with (a hand-held photo's, found)
    top_only: str | None = None

    def report(self) -> dict[str, object]:
        """The station's part of report.json."""
        return {
            "scale_source": "station",
            "dimensions": {**{k: round(v, 3) for k, v in self.dimensions.items()}, "unit": "mm"},
            "uncertainty": {k: round(v, 3) for k, v in self.uncertainty.items()},
            "position_mm": [round(v, 2) for v in self.position_mm],
            "yaw_deg": round(self.yaw_deg, 2),
            "silhouette_residual_px": round(self.residual_px, 3),
            "contrast": round(self.contrast, 1),
            "registration": {
                "source": self.registration.source,
                "shift_px": round(self.registration.shift_px, 2),
                "board_corners": self.registration.corners,
            },
            "points": [[round(float(x), 2), round(float(y), 2)] for x, y in self.points],
            "side_face": self.side_face,
            "warnings": list(self.warnings),
            "timings_ms": {k: round(v, 2) for k, v in self.timings_ms.items()},
        }


def _distorted(X: np.ndarray, cam: CameraModel, reg: Registration) -> np.ndarray:
    pts, _ = cv2.projectPoints(
        X.astype(np.float64),
        np.asarray(reg.pose.rvec),
        np.asarray(reg.pose.tvec),
        cam.matrix(),
        cam.distortion(),
    )
    return pts.reshape(-1, 2)


def reference_points(
    corners: np.ndarray, image_pts: np.ndarray, camera_centre: np.ndarray
) -> tuple[np.ndarray, str]:
    """P1..P7 of the fitted box as a person would click them.

    corners : (8, 3) board-frame corners (footprint, then top). image_pts : (8, 2) their pixels.
    The front face is the side face the camera sees largest; the second face the larger, as
    seen, of the other side it sees (right or left) and the top.
    """
    sides = [(area, idx) for name, (idx, area) in visible_faces(corners, camera_centre, image_pts).items()
             if name != "top"]
    if not sides:
        raise InputError("the fitted box shows no side face to the camera: the camera looks straight down")
    sides.sort(key=lambda s: -s[0])
    front = sides[0][1]
    bottom = [i for i in front if i < 4]
    top = [i for i in front if i >= 4]
    # left/right in the image, by the bottom corners
    bl, br = sorted(bottom, key=lambda i: image_pts[i, 0])
    tl, tr = bl + 4, br + 4
    p1, p2, p3, p6 = image_pts[tl], image_pts[tr], image_pts[br], image_pts[bl]
    assert set(top) == {tl, tr}
    top_area = abs(cv2.contourArea(image_pts[list(_FACES["top"])].astype(np.float32)))
    # The second face: the larger of the other side face and the top, as seen (a sliver of a
    # side, seen almost edge on, is no face to measure a depth on).
    if len(sides) > 1 and sides[1][0] > max(0.05 * sides[0][0], top_area):
        other = sides[1][1]
        shared = set(other) & set(front)
        if br in shared:
            far_b = next(i for i in other if i < 4 and i != br)
            return np.array([p1, p2, p3, p2, image_pts[far_b + 4], p6, image_pts[far_b]]), "right"
        far_b = next(i for i in other if i < 4 and i != bl)
        return np.array([p1, p2, p3, p1, image_pts[far_b + 4], p6, image_pts[far_b]]), "left"

    # The top: its far corners behind P1 and behind P2 (each one's other neighbour on the top).
    def behind(corner: int, other: int) -> int:
        ring = 4 + (corner - 4 + 1) % 4, 4 + (corner - 4 - 1) % 4
        return ring[0] if ring[1] == other else ring[1]

    return np.array([p1, p2, p3, p1, image_pts[behind(tl, tr)], p6, image_pts[behind(tr, tl)]]), "top"


def measure_on_station(photo: np.ndarray, station: Station) -> StationMeasurement:
    """Measure the one box resting on the station's support in `photo` (RGB (H, W, 3) uint8).

    Raises
    ------
    InputError
        A photo of another size, no plate, the camera moved beyond re-registration, no part,
        two parts, a part cut by the photo's edge, a part that is not a box resting flat.
    """
    timings: dict[str, float] = {}
    cpu: dict[str, float] = {}
    t0, c0 = time.perf_counter(), time.thread_time()
    cam = station.camera
    h, w = photo.shape[:2]
    if (w, h) != (cam.image_width, cam.image_height):
        raise InputError(
            f"the photo is {w}x{h} px, the station's camera {cam.image_width}x{cam.image_height}"
        )
    plate_u = _undistorted_plate(station)
    if plate_u is None:
        raise InputError("the station has no plate (a photo of the empty support): calibrate it with --plate")
    und = undistorter(cam)
    photo_u = und.image(photo)
    t1, c1 = time.perf_counter(), time.thread_time()
    reg = register(photo_u, plate_u, photo, station.board, cam, station.plane)
    timings.update(undistort=(t1 - t0) * 1e3, register=(time.perf_counter() - t1) * 1e3)
    cpu.update(undistort=(c1 - c0) * 1e3, register=(time.thread_time() - c1) * 1e3)
    return measure_registered(photo_u, plate_u, cam, reg, timings, cpu=cpu)


_SECOND_PART_MM = 10.0  # a blob apart from the part this wide on the support is a second part


# what a part reaching out of `region` is told, unless the caller says more
_REGION_REFUSAL = ("the part's outline reaches past the board in the photo (only the board's area is "
                   "known): lay the part on the board with the board all round it, and photograph from "
                   "higher up or use a larger board")


def _apart(others: list[tuple[float, ...]], fit: OutlineFit, K: np.ndarray, R: np.ndarray,
           t: np.ndarray) -> list[str]:
    """The smaller blobs segmentation found beside the part (`Silhouette.others`: bounding boxes
    x, y, width, height px) that lie outside the fitted box's outline, sized on the support plane
    (the longer of the box's diagonals mapped onto it: a blob seen on a support tilted away reads
    its own size, not its foreshortened one): 10 mm across or more is a second part (refused), a
    smaller one a speck (a warning naming where and how large, so it is never dropped unsaid).
    Blobs on the box's outline are pieces of the part."""
    specks = []
    hull = cv2.convexHull(project(fit.corners(), K, R, t).astype(np.float32))
    to_plane = np.linalg.inv(K @ np.column_stack([R[:, 0], R[:, 1], t]))
    outside = []
    for x, y, w, h in others:
        cx, cy = x + w / 2, y + h / 2
        if cv2.pointPolygonTest(hull, (cx, cy), True) < -(np.hypot(w, h) / 2 + 8.0):
            ends = np.array([[[x, y], [x + w, y + h], [x + w, y], [x, y + h]]], np.float64)
            mm_pts = cv2.perspectiveTransform(ends, to_plane)[0]
            mm = float(max(np.linalg.norm(mm_pts[0] - mm_pts[1]), np.linalg.norm(mm_pts[2] - mm_pts[3])))
            outside.append((cx, cy, mm if np.isfinite(mm) else np.inf))
    for cx, cy, mm in outside:
        if mm >= _SECOND_PART_MM:
            raise InputError(f"{1 + len(outside)} parts found: one part per photo (one of them about "
                             f"{mm:.0f} mm across, its outline mapped onto the support, at "
                             f"({cx:.0f}, {cy:.0f}) px): take it off the support")
        specks.append(f"a speck {mm:.0f} mm across at ({cx:.0f}, {cy:.0f}) px, apart from the part, "
                      "was left out: dust or a mark on the support?")
    return specks


def _mm_per_px_at_footprint(fit: OutlineFit, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> float:
    """Millimetres a pixel spans at the fitted footprint's centre (its distance over the focal)."""
    return float(np.linalg.norm(R @ np.array([fit.params[0], fit.params[1], 0.0]) + t) / K[0, 0])


def _hidden_sides(photo_u: np.ndarray, plate_u: np.ndarray, reg: Registration, sil: Silhouette,
                  fit: OutlineFit, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[OutlineFit, str]:
    """`fit` with the height read where the support's pattern is hidden below its top
    (`prismcore.station.hidden_sides`), where the outline's own reading is suspect (much of it
    barely differs from the support, part of it was found only where the pattern broke, or it
    gave no height): taken as the measurement where the outline gave none, else as a rival
    that widens the sigma, when that reading stands taller and its band is mostly the part's.
    Returns the fit and the warning to give ('' for none)."""
    with np.errstate(over="ignore"):
        sizes = (fit.length_mm, fit.width_mm, fit.height_mm)
    if sil.tone is None or not np.all(np.isfinite(fit.params)) or not np.all(np.isfinite(sizes)):
        return fit, ""  # a fit with no finite size is refused as degenerate, as it was
    mm_px = _mm_per_px_at_footprint(fit, K, R, t)
    flat = fit.height_mm < _MIN_SIDE_PX * mm_px  # no height (a thin footprint is refused as it was)
    if not (flat or sil.mirrored or fit.weak_fraction > _WARN_WEAK):
        return fit, ""
    reading = read_hidden_sides(photo_u, plate_u, reg.homography, sil.tone, sil.shadow_least, fit, K, R, t)
    if reading is None or not evidence_enough(reading) or reading.height_mm < 1.1 * fit.height_mm + 1.0:
        return fit, ""
    return widened(fit, reading, adopt=flat)


def measure_registered(photo_u: np.ndarray, plate_u: np.ndarray, cam: CameraModel, reg: Registration,
                       timings: dict[str, float] | None = None, *, region: np.ndarray | None = None,
                       region_refusal: str = _REGION_REFUSAL, rests_on: np.ndarray | None = None,
                       cpu: dict[str, float] | None = None) -> StationMeasurement:
    """The part measured in an undistorted photo whose support's pose is known (`reg`), against
    `plate_u` (the support as it looks without the part, registered by `reg.homography`).

    region : (H, W) bool, optional. Where the support is known (a hand-held board's area): a part
    reaching out of it is refused, with `region_refusal`'s words. rests_on : (H, W) bool, optional:
    where the part may rest (:func:`segment_part`'s). timings, cpu : each stage's wall
    and CPU (this thread's) ms are added to them.
    """
    timings = {} if timings is None else timings
    cpu = {} if cpu is None else cpu
    t2, c2 = time.perf_counter(), time.thread_time()
    sil = segment_part(photo_u, plate_u, reg.homography, rests_on=rests_on)
    if region is not None:
        edge = sil.mask & ~cv2.erode(region.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
        if edge.sum() > 0.002 * sil.area_px:
            raise PartRefusedError(region_refusal, photo_u, sil.mask)
    t3, c3 = time.perf_counter(), time.thread_time()
    K, R, t = cam.matrix(), reg.pose.rotation(), reg.pose.translation()
    # the folds and the outline's steps looked for in the part's window only
    gray = cv2.cvtColor(photo_u[sil.window], cv2.COLOR_RGB2GRAY)
    folds = fold_distance(gray, sil.mask[sil.window])
    fit = fit_outline_box(sil.contour, K, R, t, folds, sil.difference, sil.origin)
    radius = edge_radius(photo_u, fit, K, R, t)
    if radius is not None:
        # rounded edges pull the silhouette in: the box refitted as its inner box grown by them
        fit = fit_outline_box(sil.contour, K, R, t, folds, sil.difference, sil.origin,
                              radius_mm=radius.radius_mm)
    outline_rivals = fit.ambiguity_mm  # the outline's own: the second reading's gap is said apart
    hidden_warning = ""
    if fit.residual_px <= MAX_RESIDUAL_PX:  # a part refused below need not pay for the second reading
        fit, hidden_warning = _hidden_sides(photo_u, plate_u, reg, sil, fit, K, R, t)
    t4, c4 = time.perf_counter(), time.thread_time()
    timings.update(segment=(t3 - t2) * 1e3, fit=(t4 - t3) * 1e3)
    cpu.update(segment=(c3 - c2) * 1e3, fit=(c4 - c3) * 1e3)
    if fit.residual_px > MAX_RESIDUAL_PX:
        raise PartRefusedError(
            f"the part is not a box resting flat on the support: its outline is "
            f"{fit.residual_px:.1f} px (RMS) from the best such box (over {MAX_RESIDUAL_PX} px). If it is "
            "one: stand it flat on its largest face, away from other objects, and where a face matches "
            "the support's colour or mirrors it, light it from another side or put a mat of another "
            "colour under it",
            photo_u, sil.mask,
        )
    try:
        warnings = [*sil.warnings, *_apart(sil.others, fit, K, R, t)]
    except InputError as exc:  # a second part beside this one: both shown
        taken = sil.mask.copy()
        for x, y, bw, bh in sil.others:
            taken[int(y) : int(y + bh), int(x) : int(x + bw)] = True
        raise PartRefusedError(str(exc), photo_u, taken) from None
    if hidden_warning:
        warnings.append(hidden_warning)
    if fit.residual_px > WARN_RESIDUAL_PX:
        warnings.append(
            f"the outline is {fit.residual_px:.1f} px (RMS) from the fitted box: a part that is "
            "not quite a box, or resting tilted; the dimensions may be off"
        )
    L, W, H = fit.length_mm, fit.width_mm, fit.height_mm
    mm_px = _mm_per_px_at_footprint(fit, K, R, t)
    if min(L, W, H) < _MIN_SIDE_PX * mm_px or not np.all(np.isfinite([L, W, H])):
        raise PartRefusedError(
            f"the fitted box is degenerate ({L:.1f} x {W:.1f} x {H:.1f} mm, a side under "
            f"{_MIN_SIDE_PX:.0f} px): the outline found is not a box's. Most often only the "
            "top was found, its sides matching the support's colour or mirroring it: light "
            "the part from another side, or put a mat of another colour under it", photo_u, sil.mask)
    sL, sW, sH = fit.sigma_mm()
    if L >= W:
        dims, sig, yaw = (
            {"width": L, "height": H, "depth": W},
            {"width": sL, "height": sH, "depth": sW},
            fit.params[2],
        )
    else:
        dims, sig, yaw = (
            {"width": W, "height": H, "depth": L},
            {"width": sW, "height": sH, "depth": sL},
            fit.params[2] + np.pi / 2,
        )
    aL, aW, aH = outline_rivals
    rival = dict(zip(dims, (aL, aH, aW) if L >= W else (aW, aH, aL), strict=True))
    if any(rival[k] > max(1.0, _WARN_RELATIVE_SIGMA * dims[k]) for k in dims):
        warnings.append("another box fits the outline almost as well (" + ", ".join(
            f"{k} {rival[k]:.1f} mm apart" for k in dims if rival[k] > 0) + "): a face lost against the "
            "support, or a shadow or reflection taken for the part; the sigma takes it in")
    # Beyond the outline's noise: its edge is placed to a fraction of a pixel at best, the same
    # way along a whole side (blur, JPEG, the threshold), and the camera's pose is known to its
    # calibration: a floor of _SYSTEMATIC_PX at the part's distance, and 0.2 %.
    mm_per_px = float(np.linalg.norm(R @ np.array([fit.params[0], fit.params[1], -H / 2]) + t)) / K[0, 0]
    # and the rounding's radius: as read, each side moves by about its error; not read, a rounding
    # too narrow to show at this resolution (its ramp under RESOLVED_PX) may still pull the
    # silhouette in by up to _HIDDEN_SHARE of its radius on each side
    if radius is not None:
        r_sd = _RADIUS_SHARE * radius.std_mm
    else:
        hidden = min(RESOLVED_PX * mm_per_px, _HIDDEN_MAX_MM)
        r_sd = _HIDDEN_SHARE * hidden / np.sqrt(3.0)  # a radius anywhere from 0 to `hidden`
    sig = {k: float(np.sqrt(sig[k] ** 2 + (_SYSTEMATIC_PX * mm_per_px) ** 2 + (0.002 * dims[k]) ** 2
                            + r_sd**2))
           for k in dims}
    if fit.weak_fraction > _WARN_WEAK:
        warnings.append(f"{fit.weak_fraction:.0%} of the part's outline barely differs from the support "
                        "(colours alike there): its edge may have been found short; the dimensions may "
                        "be small")
    if fit.missing_fraction > _WARN_MISSING:
        warnings.append(f"{fit.missing_fraction:.0%} of the part's outline was not found where the box's "
                        "edge lies (low contrast against the support there): the dimensions may be short")
    small = []
    for k in dims:
        if not np.isfinite(sig[k]) or sig[k] > _WARN_RELATIVE_SIGMA * dims[k] + 1.0:
            warnings.append(
                f"{k} is poorly determined from this view ({dims[k]:.1f} +- {sig[k]:.1f} mm): "
                "turn the part so two of its sides face the camera"
            )
        elif sig[k] > _WARN_RELATIVE_SIGMA * dims[k]:
            small.append(k)
    if small:
        # A 20 mm side at 640x512 read 6 % long, within its sigma, and went unsaid. The cause is
        # said where it is the part's size in the photo; else the outline's own warnings say it.
        listed = ", ".join(f"{k} {dims[k]:.1f} +- {sig[k]:.2f}" for k in small)
        span = min(dims[k] for k in small) / mm_per_px
        cause = (f": the part spans {span:.0f} px at its smallest; a closer camera or a larger photo "
                 "measures it better" if span < _SMALL_SPAN_PX else
                 ": the outline found does not pin the box down")
        warnings.append(f"{listed} mm: uncertain by over {_WARN_RELATIVE_SIGMA:.0%}{cause}")
    corners = fit.corners()
    image_pts = _distorted(corners, cam, reg)
    points, side = reference_points(corners, project(corners, K, R, t), -R.T @ t)
    # the points in the photo as taken: the same corners through the lens
    lookup = {tuple(np.round(p, 6)): i for i, p in enumerate(project(corners, K, R, t))}
    points = np.array([image_pts[lookup[tuple(np.round(p, 6))]] for p in points])
    along: str | None = None
    if _sides_seen(corners, project(corners, K, R, t), -R.T @ t) < 2:
        # One side face towards the camera: the footprint's other side is read on the top face
        # alone, foreshortened (seen 13 % off on renders with a sigma of 0.3 mm): say so, and
        # widen its sigma to what such views are seen to miss by.
        p1, p2 = _corner_at(points[0], image_pts), _corner_at(points[1], image_pts)
        front_mm = float(np.linalg.norm(corners[p1] - corners[p2]))
        along = "width" if abs(front_mm - dims["width"]) > abs(front_mm - dims["depth"]) else "depth"
        sig[along] = max(sig[along], _TOP_ONLY_SIGMA * dims[along])
        warnings.append(f"{along} is seen on the top face only (one side of the part faces the camera): "
                        f"{dims[along]:.1f} +- {sig[along]:.1f} mm; turn the part so two of its sides "
                        "face the camera")
    return StationMeasurement(
        dimensions=dims,
        uncertainty=sig,
        position_mm=(float(fit.params[0]), float(fit.params[1])),
        yaw_deg=float(np.degrees(yaw) % 180),
        residual_px=fit.residual_px,
        contrast=sil.contrast,
        registration=reg,
        fit=fit,
        points=points,
        side_face=side,
        camera=cam,
        warnings=warnings,
        top_only=along,
        timings_ms=timings,
        cpu_ms=cpu,
    )

"""Zero-click: find a box in a photo, its visible faces and its reference points P1..P7.

The search, on a copy of the photo about 640 px wide (inside the region of interest, if given):

1. Colour edges (Canny on each Lab channel), thickened so a face's outline closes.
2. The regions the edges enclose; those whose outline is a convex quadrilateral are face
   candidates (a printed label is a hole in its face, not a face of its own).
3. Faces that share an edge (two corners each) form a box: two faces, or three around one
   corner. The top face is the one above the others; the front the larger of the upright
   ones, the other the side (right or left), else the top.
4. The box around the hint, or the largest near the image centre; a second candidate nearly as
   large is an ambiguity the caller must settle with a hint.
5. Full resolution: the engine's own plan (sub-pixel edge fits and the free-focal box fit,
   `pipeline.plan_scan`) places the corners; run twice, the second from the first's corners,
   so that its click residuals measure how well a box explains the edges.
6. When no box passes: the largest faces' neighbours are proposed from the line segments and
   the colour change along them (`locate_faces`), and those boxes go through 4 and 5 alike.
7. When still none passes: two faces whose fold is too faint to split their region are split
   at it; their region's outline, a pentagon or a quad (the bends at the fold's ends too
   shallow to see), is cut where the colour change runs its whole length in a direction
   between the box's two edges beside it (`_pentagon_box`, `_quad_box`).

Steps 1-2 are `locate.outlines`, 3 `locate.boxes`, 7 `locate.folds`, the second face proposed
from one (6) `locate.second_face`; here: choosing, measuring and judging a box (4, 5), and the
result.

The confidence combines the edge fits' support, the box fit's residuals and how far the
corners moved from the regions' outlines; below `CONFIDENCE_MIN` the result carries the reason
and no caller should measure it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from prismcore.errors import InputError
from prismcore.geometry.edges import intersect
from prismcore.geometry.faces import SideFace
from prismcore.locate.boxes import _boxes, _label, _score
from prismcore.locate.folds import _split_boxes
from prismcore.locate.outlines import _SAMPLINGS, _all_faces, _Box, _clockwise, _Quad, _Work
from prismcore.locate.second_face import propose_neighbours
from prismcore.spec import ReferencePoints, ScanSpec, search_area_problem

__all__ = ["CONFIDENCE_MIN", "CONFIDENCE_WARN", "Found", "find_points", "resolve_points"]

CONFIDENCE_MIN = 0.6
CONFIDENCE_WARN = 0.8  # accepted below this: with a warning to check the points
WORK_WIDTH = 640  # px: the search runs on a copy this wide
_AMBIGUOUS = 0.6  # a runner-up this large (relative) is a second box
_PER_CLUSTER = 3  # boxes over one place (other faces or neighbours) measured before the next
_ATTEMPTS = 3  # candidates given the full fit before giving up


@dataclass(frozen=True)
class Found:
    """What the search found.

    Attributes
    ----------
    points : ReferencePoints or None
        P1..P7, image (x, y) px (all seven), or None when nothing box-like was found.
    side_face : {"right", "left", "top"} or None
        The second face P4, P5, P7 mark.
    confidence : float
        0-1; `CONFIDENCE_MIN` and above: the points may be measured.
    reason : str or None
        Why the result must not be measured (a person can act on it); None when accepted.
    faces : tuple of ndarray
        The face quads found, each (4, 2) float64 image px (for overlays).
    candidates : int
        How many box candidates the search saw.
    fit_rms_px : float or None
        RMS distance (px) between the corners of the two fitting passes (see the module).
    timings_ms : dict
        Stage -> milliseconds.
    warnings : tuple of str
        An accepted result below `CONFIDENCE_WARN` says to check the points, as does one that
        is not `stable`.
    stable : bool
        False when the decision sits on a knife edge: the box rests on a face only one of the
        search's two samplings of the photo found, so a slight change of the photo (a grey
        level, a re-encode, a sub-pixel shift: another machine's decoder) may lose it.
    """

    points: ReferencePoints | None
    side_face: SideFace | None
    confidence: float
    reason: str | None
    faces: tuple[np.ndarray, ...] = ()
    candidates: int = 0
    fit_rms_px: float | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    stable: bool = True

    @property
    def ok(self) -> bool:
        return self.reason is None

    def report(self) -> dict[str, Any]:
        """The JSON-ready summary report.json keeps."""
        return {"points_source": "auto", "confidence": round(self.confidence, 3),
                "side_face": self.side_face, "reason": self.reason,
                "points": None if self.points is None else
                {k: [round(v[0], 2), round(v[1], 2)] for k, v in self.points.as_dict().items()},
                "candidates": self.candidates, "warnings": list(self.warnings), "stable": self.stable,
                "fit_rms_px": None if self.fit_rms_px is None else round(self.fit_rms_px, 3)}


def _parse_roi(roi: tuple[float, float, float, float] | None, shape: tuple[int, ...]
               ) -> tuple[int, int, int, int]:
    h, w = shape[:2]
    if roi is None:
        return 0, 0, w, h
    x0, y0, x1, y1 = (float(v) for v in roi)  # search_area_problem has checked it
    return (max(0, math.floor(x0)), max(0, math.floor(y0)),
            min(w, math.ceil(x1) + 1), min(h, math.ceil(y1) + 1))


def _contains(box: _Box, xy: np.ndarray) -> float:
    """Signed distance (px, positive inside) of xy from the box's outline."""
    return float(cv2.pointPolygonTest(box.hull.astype(np.float32), (float(xy[0]), float(xy[1])), True))


_PNP_MAX = 0.03  # reprojection RMS over the box's image size: above it, not a box


def _box_model(width: float, depth: float, side_face: SideFace) -> dict[str, np.ndarray]:
    """Model corners (height 1; X right, Y down, Z into the object) by point name."""
    pts = {"p1": [0, 0, 0], "p2": [width, 0, 0], "p3": [width, 1, 0], "p6": [0, 1, 0]}
    far = {"right": ([width, 0, depth], [width, 1, depth]), "left": ([0, 0, depth], [0, 1, depth]),
           "top": ([0, 0, depth], [width, 0, depth])}[side_face]
    pts.update(p5=far[0], p7=far[1])
    return {k: np.asarray(v, dtype=np.float64) for k, v in pts.items()}


def _box_likeness(points: dict[str, np.ndarray], side_face: SideFace, shape: tuple[int, ...]) -> float:
    """How far (relative to the box's image size) the points are from any box's projection.

    A quick screen before the engine's fit, which on points that fit no box can take seconds:
    the faces' aspects from their homographies, then a PnP pose for a few focal lengths.
    """
    from prismcore.geometry.faces import clicked_quads
    from prismcore.geometry.perspective import rectangle_pose

    h, w = shape[:2]
    ref = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in points.items()})
    quads = clicked_quads(ref, two_photo=False, side_face=side_face)
    names = ("p1", "p2", "p3", "p6", "p5", "p7")
    image_pts = np.array([points[n] for n in names])
    size = float(np.linalg.norm(np.ptp(image_pts, axis=0)))
    best = math.inf
    for f in (0.8 * w, 1.2 * w, 2.0 * w, 4.0 * w):
        K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
        try:
            width = rectangle_pose(K, quads.front)[0]
            aspect = rectangle_pose(K, quads.side)[0]
        except (np.linalg.LinAlgError, cv2.error):
            continue
        depth = width / aspect if side_face == "top" else aspect
        if not (math.isfinite(width) and math.isfinite(depth) and width > 0 and depth > 0):
            continue
        model = _box_model(width, depth, side_face)
        obj = np.array([model[n] for n in names])
        ok, rvec, tvec = cv2.solvePnP(obj, image_pts, K, None, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            continue
        proj = cv2.projectPoints(obj, rvec, tvec, K, None)[0].reshape(-1, 2)
        best = min(best, float(np.sqrt(np.mean(np.sum((proj - image_pts) ** 2, axis=1)))) / size)
    return best


def _refined(image: np.ndarray, points: dict[str, np.ndarray], side_face: SideFace, *,
             rough: bool = False) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The engine's plan from these points: the fitted box's corners and the plan's fit/edges.

    The focal length is fitted too (from points far from any box that can take the solver
    seconds: `_box_likeness` screens them out first).

    Raises InputError when the plan refuses the points (a fit guard, a degenerate face).
    """
    from prismcore.scan.pipeline import plan_scan

    ref = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in points.items()})
    spec = ScanSpec(image="auto", points=ref, side_face=side_face)
    plan = plan_scan(spec, image, rough_points=rough)
    front, side = plan.faces[0].region, plan.faces[1].region
    if side_face == "right":
        named = {"p4": side[0], "p5": side[1], "p7": side[2]}
    elif side_face == "left":
        named = {"p4": side[1], "p5": side[0], "p7": side[3]}
    else:
        named = {"p4": side[3], "p5": side[0], "p7": side[1]}
    out = {"p1": front[0], "p2": front[1], "p3": front[2], "p6": front[3], **named}
    supports = [f.support if f.fitted else 0.0 for fits in plan.edges.values() for f in fits]
    # Where the fitted edges meet against where the box model puts the corners: the clicks
    # (the previous pass's model corners) cannot tell whether a box explains the edges.
    gaps = []
    for face, region in (("front", front), ("side", side)):
        fits = plan.edges.get(face, [])
        for i in range(len(fits)):
            a, b = fits[i - 1], fits[i]
            if a.fitted and b.fitted:
                with np.errstate(divide="ignore", invalid="ignore"):
                    corner = intersect(a.line, b.line)
                gaps.append(float(np.linalg.norm(corner - region[i])) if np.isfinite(corner).all()
                            else math.inf)
    info = {"fit": plan.fit, "supports": supports, "focal_px": plan.camera.get("focal_px"),
            "perspective": plan.dimensions.perspective, "gaps": gaps}
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}, info


def _confidence(first: dict[str, np.ndarray], second: dict[str, np.ndarray], info: dict[str, Any],
                width: int) -> tuple[float, float]:
    """Confidence 0-1 and the RMS (px) between the two passes' corners."""
    moved = np.array([np.linalg.norm(first[k] - second[k]) for k in first])
    rms = float(np.sqrt(np.mean(moved ** 2)))
    supports = np.asarray(info["supports"], dtype=np.float64)
    # One side partly hidden (a label at the edge, a background of the box's colour) is common
    # and harmless while the box model meets every fitted edge (the gaps term); a side with no
    # edge at all is not.
    weakest = float(np.clip((supports.min() - 0.2) / 0.3, 0, 1))
    c_edges = weakest ** 0.5 * float(np.clip(supports.mean(), 0, 1))
    c_fit = math.exp(-((rms / 1.5) ** 2))
    c_resid = math.exp(-((float(info["fit"].get("rms_px", 0.0)) / 2.5) ** 2))
    gaps = np.asarray(info["gaps"] or [math.inf])
    gap_rms = float(np.sqrt(np.mean(gaps ** 2)))
    c_model = math.exp(-((gap_rms / 1.5) ** 2)) * math.exp(-((float(gaps.max()) / 4.0) ** 2))
    focal = info.get("focal_px")
    c_focal = 1.0 if focal is None or 0.25 * width <= focal <= 6 * width else 0.3
    return float(np.clip(c_edges * c_fit * c_resid * c_model * c_focal, 0, 1)), rms


def find_points(image: np.ndarray, *, hint: tuple[float, float] | None = None,
                roi: tuple[float, float, float, float] | None = None,
                threshold: float = CONFIDENCE_MIN) -> Found:
    """Find a box in a photo and its reference points P1..P7.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        RGB, uint8 (or float 0-255).
    hint : (float, float), optional
        Image (x, y) px on the box wanted: the box whose outline holds it is chosen.
    roi : (x0, y0, x1, y1), optional
        Image px: only a box inside this region is looked for.
    threshold : float
        Results below this confidence carry a reason (are refused).

    Returns
    -------
    Found
        Points in full-image px; `reason` set when the result must not be measured.

    Raises
    ------
    InputError
        For an image that is not RGB, or a hint/roi outside the image.
    """
    timings: dict[str, float] = {}
    start, start_cpu = time.perf_counter(), time.process_time()
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 16:
        raise InputError(f"image must be RGB of shape (H, W, 3), at least 16x16, got {image.shape}")
    h, w = image.shape[:2]
    if (problem := search_area_problem(hint, roi, w, h)) is not None:
        raise InputError(problem[1])
    x0, y0, x1, y1 = _parse_roi(roi, image.shape)
    crop = image[y0:y1, x0:x1]
    scale = min(1.0, WORK_WIDTH / max(crop.shape[1], 1))
    small = crop if scale == 1.0 else cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    small = np.clip(small, 0, 255).astype(np.uint8)
    offset = np.array([x0, y0], dtype=np.float64)

    def full(p: np.ndarray) -> np.ndarray:  # work px -> image px (pixel centres)
        return np.asarray((p + 0.5) / scale - 0.5 + offset, dtype=np.float64)

    quads, silhouettes, work = _all_faces(small)
    boxes = _boxes(quads) + silhouettes
    timings["search"] = (time.perf_counter() - start) * 1000
    # The process's CPU time too: on a shared machine the wall time mostly measures the load.
    timings["search_cpu"] = (time.process_time() - start_cpu) * 1000
    found_faces = tuple(full(q.corners) for q in quads)
    hint_work = None if hint is None else (np.array(hint) - offset + 0.5) * scale - 0.5
    if hint is not None and hint_work is not None and boxes:
        boxes = [b for b in boxes if _contains(b, hint_work) > -3.0]
        if not boxes:
            return Found(None, None, 0.0, f"no box found around the hint ({hint[0]:g},{hint[1]:g})",
                         found_faces, 0, timings_ms=timings)

    def clock() -> None:  # the search's time so far, the corner fits' left out
        timings["search"] = (time.perf_counter() - start) * 1000 - timings.get("fit", 0.0)
        timings["search_cpu"] = ((time.process_time() - start_cpu) * 1000
                                 - timings.get("fit_cpu", 0.0))

    what = "region" if roi is not None else "photo"
    result = _choose(image, boxes, small.shape[:2], full, timings, clock, threshold, hint is not None, what)
    fallbacks: tuple[tuple[str, Callable[[], list[_Box]]], ...] = (
        # One face found, its neighbour's region open: propose the neighbour from lines.
        ("propose", lambda: _proposed_boxes(quads, work, small.shape, hint_work)),
        # Two faces merged into one region, the fold between them too faint for its edges.
        ("split", lambda: _split_boxes(work, small.shape, hint_work)),
    )
    for stage, more_boxes in fallbacks:
        if result is not None and result.ok:
            break
        t0 = time.perf_counter()
        more = more_boxes()
        timings[stage] = (time.perf_counter() - t0) * 1000
        if more:
            other = _choose(image, more, small.shape[:2], full, timings, clock, threshold,
                            hint is not None, what)
            if other is not None and other.ok:
                result = other
    if result is None:
        return Found(None, None, 0.0, _nothing(quads, small.shape), found_faces, 0, timings_ms=timings)
    timings["total"] = (time.perf_counter() - start) * 1000
    return result


_PROPOSE_FROM = 3  # the largest faces (near the centre) a neighbour is proposed for


def _proposed_boxes(quads: list[_Quad], work: _Work, shape: tuple[int, ...],
                    hint_work: np.ndarray | None) -> list[_Box]:
    """Boxes of a face found and a neighbour proposed from the line segments
    (`locate_faces.propose_neighbours`), one per side of each large face."""
    h, w = shape[:2]
    big = [q for q in quads if q.area > 0.02 * h * w]
    if hint_work is not None:
        big = [q for q in big if cv2.pointPolygonTest(q.corners.astype(np.float32),
                                                      (float(hint_work[0]), float(hint_work[1])),
                                                      True) > -0.5 * math.sqrt(q.area)]
    if not big:
        return []
    grad = work.gradient
    centre = np.array([w / 2, h / 2])
    big.sort(key=lambda q: -q.area * (1.0 - 0.6 * np.linalg.norm(q.corners.mean(axis=0) - centre)
                                      / math.hypot(w / 2, h / 2)))
    out = []
    for face in big[:_PROPOSE_FROM]:
        for corners, _ in propose_neighbours(face.corners, work.segments, grad, (h, w)):
            proposed = _clockwise(corners)
            # Proposed from the first sampling's line segments only: not known to be stable.
            proposed.seen = face.seen & 0b01
            faces = [face, proposed]
            allc = np.concatenate([f.corners for f in faces]).astype(np.float32)
            hull = cv2.convexHull(allc).reshape(-1, 2).astype(np.float64)
            out.append(_Box(faces, float(cv2.contourArea(hull.astype(np.float32))), hull.mean(axis=0),
                            hull))
    return out


def _choose(image: np.ndarray, boxes: list[_Box], shape: tuple[int, int],
            full: Callable[[np.ndarray], np.ndarray], timings: dict[str, float],
            clock: Callable[[], None], threshold: float, hinted: bool, what: str) -> Found | None:
    """The best of the candidate boxes measured (None when none passes the PnP screen); a second
    that fits as well makes it ambiguous unless a hint chose."""
    # The quick screen first: pairs of flat shapes that share an edge are no box.
    labelled = []
    for box in boxes:
        named = _label(box)
        if named is None:
            continue
        work, side_face = named
        first_in = {k: full(v) for k, v in work.items()}
        if _box_likeness(first_in, side_face, image.shape) < _PNP_MAX:
            labelled.append((box, first_in, side_face))
    clock()
    if not labelled:
        return None
    labelled.sort(key=lambda item: -_score(item[0], shape[:2]))
    # Boxes built from the same faces (two of a box's three) are one box, not two; but the
    # largest of them is not always the right one (a neighbour proposed on the wrong side, two
    # faces merged into one quad), so the next few over the same place are measured too.
    distinct = [labelled[0]]
    members = [[labelled[0]]]
    for item in labelled[1:]:
        for d, m in zip(distinct, members, strict=True):
            if not (_contains(d[0], item[0].centre) < 0 and _contains(item[0], d[0].centre) < 0):
                m.append(item)
                break
        else:
            distinct.append(item)
            members.append([item])
    result: Found | None = None
    chosen = 0
    tries = [(rank, item) for rank, group in enumerate(members[:_ATTEMPTS]) for item in group[:_PER_CLUSTER]]
    for rank, (box, first_in, side_face) in tries:
        attempt = _measure(image, first_in, side_face, box, full, timings, threshold, len(distinct))
        if result is None or (not result.ok and attempt.confidence > result.confidence):
            result, chosen = attempt, rank
        if attempt.ok:
            break
    assert result is not None
    if result.ok and not hinted:
        best = _score(distinct[chosen][0], shape[:2])
        for box, first_in, side_face in distinct[chosen + 1:chosen + 2]:
            if _score(box, shape[:2]) < _AMBIGUOUS * best:
                break
            other = _measure(image, first_in, side_face, box, full, timings, threshold, len(distinct))
            if other.ok:
                # A second box that fits as well: which one is meant is the caller's to say.
                result = Found(result.points, result.side_face, min(result.confidence, threshold * 0.99),
                               f"2 candidate boxes in the {what}: give a hint (a point on the box "
                               "wanted) or a region", result.faces, len(distinct), result.fit_rms_px,
                               timings)
    return result


def _nothing(quads: list[_Quad], shape: tuple[int, ...]) -> str:
    big = [q for q in quads if q.area > 0.02 * shape[0] * shape[1]]
    if big:
        return "only one face visible: a box needs two faces in the photo (front and a side or the top)"
    return "no box found"


def _measure(image: np.ndarray, first_in: dict[str, np.ndarray], side_face: SideFace, box: _Box,
             full: Callable[[np.ndarray], np.ndarray], timings: dict[str, float], threshold: float,
             candidates: int) -> Found:
    """Place the corners with the engine's plan (twice) and rate them."""
    t0, t0_cpu = time.perf_counter(), time.process_time()

    def clock() -> None:
        timings["fit"] = timings.get("fit", 0.0) + (time.perf_counter() - t0) * 1000
        timings["fit_cpu"] = timings.get("fit_cpu", 0.0) + (time.process_time() - t0_cpu) * 1000

    faces = tuple(full(f.corners) for f in box.faces)
    try:
        first, _ = _refined(image, first_in, side_face, rough=True)
        second, info = _refined(image, first, side_face)
    except InputError as exc:
        clock()
        pts = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in first_in.items()})
        return Found(pts, side_face, 0.0, f"the box found does not fit a box model ({exc})", faces,
                     candidates, None, timings)
    clock()
    confidence, rms = _confidence(first, second, info, image.shape[1])
    h, w = image.shape[:2]
    inside = all(-0.5 <= p[0] <= w - 0.5 and -0.5 <= p[1] <= h - 0.5 for p in second.values())
    if not inside:
        confidence = 0.0
    pts = ReferencePoints.model_validate({k: (float(v[0]), float(v[1])) for k, v in second.items()})
    reason = None
    if confidence < threshold:
        reason = (f"the box found is uncertain (confidence {confidence:.2f} < {threshold:g}): its "
                  "edges are weak or a box does not explain them; give a hint or a region, or "
                  "click the points")
    warnings: tuple[str, ...] = ()
    if reason is None and confidence < CONFIDENCE_WARN:
        warnings = (f"points found automatically with a modest confidence ({confidence:.2f}): "
                    "check them on the overlay",)
    stable = all(f.seen == _SAMPLINGS for f in box.faces)
    if reason is None and not stable:
        warnings += (_UNSTABLE,)
    return Found(pts, side_face, confidence, reason, faces, candidates, rms, timings, warnings, stable)


_UNSTABLE = ("a face of this box was found in only one of two samplings of the photo (its region "
             "closes on one, not the other): a slight change of the photo may lose the box; check "
             "the points on the overlay")


def resolve_points(spec: ScanSpec, image: np.ndarray) -> tuple[ScanSpec, Found]:
    """A spec with points "auto" made into one with the points found in `image`.

    Returns the spec to measure (points and side face filled in, `auto_points` cleared) and
    what the search found.

    Raises
    ------
    InputError
        With the search's reason when it refuses (no box, two boxes, one face, uncertain).
    """
    if spec.auto_points is None:
        raise InputError("resolve_points needs a spec with points \"auto\"")
    found = find_points(image, hint=spec.auto_points.hint, roi=spec.auto_points.roi)
    if not found.ok or found.points is None:
        raise InputError(f"points auto: {found.reason}")
    return spec.model_copy(update={"points": found.points, "side_face": found.side_face,
                                   "auto_points": None}), found

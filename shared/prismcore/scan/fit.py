"""The box measured from the faces the points mark: each face's edges refined to sub-pixel lines,
the dimensions from the default method's perspective fit (or the square-on model, or the paper's),
and the checks that the fit is the box the points mark (edges that snapped to a printed border
give way to the clicks; a fitted corner far from its click is a warning, very far a refusal).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from prismcore.errors import InputError
from prismcore.geometry.edge_checks import EdgeUse, clicked_fit, judge_edge
from prismcore.geometry.edges import Bound, EdgeFit, inward, line_through, refine_quad
from prismcore.geometry.faces import FaceQuads, clicked_quads, quad_labels, shared_edges, validate_quad
from prismcore.geometry.perspective import NOISE_CLICK_PX, FaceEvidence
from prismcore.scan.focal import Focal
from prismcore.scan.measure import (
    Dimensions,
    camera_matrix,
    measure_affine,
    measure_box,
    measure_perspective,
    obliqueness,
    perspective_cost,
    square_on_cost,
)
from prismcore.spec import KnownEdge, ScanSpec

__all__ = ["FIT_FAIL_FRACTION", "FIT_FAIL_PX", "FIT_WARN_PX", "FOCAL_MAX_REL_STD", "OBLIQUE_WARN",
           "SEARCH_PX", "SIDE_NAMES", "SNAP_CHI2", "SNAP_CLICKS_BETTER", "SNAP_SIGMAS",
           "SNAP_SUSPECT_RMS_PX", "EdgeUses", "edge_use_json", "fit_guard", "measure_faces",
           "refine_faces", "unless_snapped"]

FIT_WARN_PX = 3.0  # a click this far from the fitted model's corner is worth a look
FIT_FAIL_PX = 25.0  # ... and this far (or 5 % of the face's size) means the fit is wrong
FIT_FAIL_FRACTION = 0.05
SNAP_SUSPECT_RMS_PX = 5.0  # a fit to the refined edges this far (RMS) from the clicks is suspect...
SNAP_CLICKS_BETTER = 3.0  # ... and is replaced when the clicks alone fit a box this many times closer
SNAP_SIGMAS = 3.0
"""The edges' box is kept while each dimension lies within this many (combined) sigmas of the
clicks' own box: the edges measure the clicks' box more precisely, or they are another box."""
SNAP_CHI2 = 40.0
"""The clicks' squared distances (in click variances, NOISE_CLICK_PX) that the edges' box may add
to what the clicks alone fit: about chi-square's 99.97 % point for the 14 coordinates of seven
clicks. Beyond it the edges moved correct clicks farther than their noise explains, and the
clicks win (28, the 99.9 % point for a box's ~9 parameters, also took clicks 4 px off on clean
renders for wrong: `tests/engine/scan/test_accuracy.py`)."""
FOCAL_MAX_REL_STD = 0.25  # a fitted focal less sure than this is "not determined"
OBLIQUE_WARN = 0.01  # warn when the square-on model costs more than 1 % on some dimension
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
SIDE_NAMES = ("top", "right", "bottom", "left")
EdgeUses = dict[str, list[EdgeUse]]


def edge_use_json(uses: EdgeUses) -> dict[str, list[dict[str, str]]]:
    """report.json's fit.edges: per face, per side, what it rests on and why."""
    return {face: [{"side": name, **u.as_json()} for name, u in zip(SIDE_NAMES, sides, strict=True)]
            for face, sides in uses.items()}


def _judged(quad: np.ndarray, fits: list[EdgeFit], known: dict[int, EdgeFit], folds: set[int],
            known_uses: dict[int, EdgeUse]) -> list[EdgeUse]:
    """What each side rests on before the whole fit's check (`edge_checks.judge_edge`); a side
    shared with the front face rests on what the front's did."""
    return [known_uses[i] if i in known else judge_edge(fit, outline=i not in folds)
            for i, fit in enumerate(fits)]


def refine_faces(
    spec: ScanSpec, images: list[np.ndarray], clicked: FaceQuads, warnings: list[str]
) -> tuple[FaceQuads, dict[str, list[EdgeFit]], EdgeUses]:
    """Edge-fit both faces; the single-photo side face reuses the front's edge it shares. Each
    side keeps its refined edge only where the photo clearly shows it (`_judged`); the third
    result says, per face and side, which was used and why."""
    def search(quad: np.ndarray) -> float:
        sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
        return float(min(SEARCH_PX, 0.3 * sides.min()))

    fits: dict[str, list[EdgeFit]] = {}
    uses: EdgeUses = {}
    refined = {}
    jobs = [("front", 0, clicked.front), ("side", 1 if spec.two_photo else 0, clicked.side)]
    for name, index, quad in jobs:
        r = search(quad)
        known: dict[int, EdgeFit] | None = None
        extra: dict[int, tuple[Bound, ...]] | None = None
        folds: set[int] = set()
        known_uses: dict[int, EdgeUse] = {}
        if not spec.two_photo:
            front_edge, side_edge = shared_edges(clicked.side_face)
            folds = {front_edge if name == "front" else side_edge}
            if name == "side":
                known = {side_edge: fits["front"][front_edge]}
                known_uses = {side_edge: uses["front"][front_edge]}
            else:
                # In one photo the side face lies beyond the front's shared edge: that edge must
                # not be taken from the side face's far side.
                o, ref = (side_edge + 2) % 4, clicked.side[(side_edge + 1) % 4]
                far = inward(line_through(clicked.side[o], clicked.side[(o + 1) % 4]), ref)
                extra = {front_edge: ((far, 0.5 * float(far[:2] @ ref + far[2])),)}
        corners, face_fits = refine_quad(images[index], quad, search_px=r, known=known,
                                         extra_bounds=extra)
        face_uses = _judged(quad, face_fits, known or {}, folds, known_uses)
        moved = np.linalg.norm(corners - quad, axis=1).max() if np.isfinite(corners).all() else np.inf
        try:
            if moved > 3 * r + 4:
                raise InputError("refined corners moved too far")
            validate_quad(corners, f"refined {name} face", images[index].shape)
        except InputError:
            warnings.append(f"{name} face: edges not found near the clicks; clicked corners used")
            corners = quad
            face_fits = [clicked_fit(quad[i], quad[(i + 1) % 4], f) for i, f in enumerate(face_fits)]
            face_uses = [EdgeUse("click", "the edges found moved the corners too far") for _ in face_uses]
        if not all(f.fitted for f in face_fits):
            missing = [s for s, f in zip(SIDE_NAMES, face_fits, strict=True) if not f.fitted]
            warnings.append(f"{name} face: no clear edge along the {', '.join(missing)} side; "
                            "the click was used there")
        fits[name], refined[name], uses[name] = face_fits, corners, face_uses
    return FaceQuads(refined["front"], refined["side"], clicked.front_complete,
                     clicked.side_complete, clicked.side_face), fits, uses


def perspective_focal(focal: Focal, image: np.ndarray) -> float:
    """The focal length (px) the square-on model's perspective cost is read through: the one
    known (given, camera, EXIF, pooled), else the photo's diagonal (a 43 mm lens on 35 mm film;
    a phone's 26 mm main camera sees more perspective still)."""
    return focal.focal_px or float(np.hypot(image.shape[0], image.shape[1]))


def _oblique_warning(spec: ScanSpec, quads: FaceQuads, dims: Dimensions, warnings: list[str],
                     focal_px: float) -> None:
    """Say how oblique a single photo measured with the square-on model is, and what it costs:
    the obliqueness the model ignores, on its worst dimension, and the perspective it cannot
    see, on every dimension measured (both are in their ±)."""
    view = obliqueness(quads.front, quads.side, quads.side_face)
    cost = np.zeros(3) if view is None else square_on_cost(view, spec.scale)
    unseen = perspective_cost(quads.front, quads.side, focal_px)
    if cost.max() <= OBLIQUE_WARN and unseen <= OBLIQUE_WARN:
        return
    names = ("width", "height", "depth")
    given = spec.scale.edge if isinstance(spec.scale, KnownEdge) else None
    measured = " and the ".join(n for n in names if n != given)
    model = "the paper's method" if spec.method == "paper" else "the square-on model"
    fix = "" if spec.method == "paper" else "; mark P6 and P7 to have perspective corrected"
    second = "top face" if quads.side_face == "top" else "side face"
    said = f"oblique photo measured with {model}: "
    if view is not None and cost.max() > OBLIQUE_WARN:
        said += (f"the front face is seen {view.front_deg:.0f}° and the {second} {view.side_deg:.0f}° "
                 f"off square-on, which costs about {cost.max():.0%} on the {names[int(np.argmax(cost))]}; ")
    said += (f"the perspective it cannot see may cost about {unseen:.0%} on the {measured} (in their ±)"
             f"{fix}")
    warnings.append(said)


def measure_faces(spec: ScanSpec, quads: FaceQuads, marked: FaceQuads, fits: dict[str, list[EdgeFit]],
             images: list[np.ndarray], focal: Focal, warnings: list[str]
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
    unseen_focal = None if spec.two_photo else perspective_focal(focal, images[0])
    dims = measure_affine(quads.front, quads.side, spec.scale, focal_px=focal.focal_px,
                          two_photo=spec.two_photo, view=view,
                          corner_noise_px=NOISE_CLICK_PX,
                          clicked=(marked.front, marked.side) if fits else None, side_face=face,
                          perspective_focal_px=unseen_focal)
    if unseen_focal is not None:
        _oblique_warning(spec, shape, dims, warnings, unseen_focal)
    return dims, quads, camera


def _click_distances(marked: FaceQuads, model: FaceQuads) -> np.ndarray:
    """Distances (px) between the clicked points and the model's corners they mark."""
    labels = quad_labels(marked)
    return np.array([np.linalg.norm(corner - click)
                     for face in ("front", "side")
                     for label, click, corner in zip(labels[face == "side"], getattr(marked, face),
                                                     getattr(model, face), strict=True) if label is not None])


def _apart(a: Dimensions, b: Dimensions) -> float:
    """The largest difference between two measures of one box, in their combined sigmas."""
    if a.uncertainty is None or b.uncertainty is None:
        return 0.0
    worst = 0.0
    for x, y, sx, sy in zip((a.width, a.height, a.depth), (b.width, b.height, b.depth), a.uncertainty,
                            b.uncertainty, strict=True):
        sigma = float(np.hypot(sx, sy))
        if sigma > 0:
            worst = max(worst, abs(x - y) / sigma)
    return worst


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(d)))) if d.size else 0.0


def unless_snapped(spec: ScanSpec, marked: FaceQuads, fits: dict[str, list[EdgeFit]],
                    images: list[np.ndarray], focal: Focal, warnings: list[str],
                    refined: tuple[Dimensions, FaceQuads, dict[str, Any]], uses: EdgeUses,
                    noise_rules: bool = True,
                    ) -> tuple[Dimensions, FaceQuads, dict[str, Any], dict[str, list[EdgeFit]], EdgeUses]:
    """The box fitted to the refined edges, unless it moves the clicks more than their noise explains.

    Edge refinement takes the consensus line near each clicked side; on a real box that can be a
    printed border, a lid's seam or the background past a corner (a real video: 10-20 px off), and
    edges used on some sides with the clicks on the others can make a box no click agrees with.
    The clicks alone fit a box too; the edges' box is kept while the squared distances it puts
    between the clicks and their corners exceed the clicks' own fit's by no more than click noise
    explains (SNAP_CHI2 click variances, NOISE_CLICK_PX), or by no more than SNAP_CLICKS_BETTER
    times when it is within SNAP_SUSPECT_RMS_PX (clicks noisier than stated, as a hurried user's).
    """
    dims, quads, camera = refined
    if not any(f.fitted for face in fits.values() for f in face):
        return dims, quads, camera, fits, uses
    d = _click_distances(marked, quads)
    rms, variance = _rms(d), NOISE_CLICK_PX**2
    plain = {n: [EdgeFit(line_through(q[i], q[(i + 1) % 4]), 0.0, 0.0, False) for i in range(4)]
             for n, q in (("front", marked.front), ("side", marked.side))}
    scratch: list[str] = []
    alt = measure_faces(spec, marked, marked, plain, images, focal, scratch)
    alt_d = _click_distances(marked, alt[1])
    alt_rms = _rms(alt_d)
    moved = float(np.sum(d**2) - np.sum(alt_d**2)) / variance
    apart = _apart(dims, alt[0])
    # The clicks win on the noise rules only when they are a box themselves: a click on the wrong
    # corner makes the clicks' own fit far from them too, and the fit guard must see the edges' box.
    own = noise_rules and float(np.sum(alt_d**2)) / variance <= SNAP_CHI2
    if not ((alt_rms * SNAP_CLICKS_BETTER < rms and rms > SNAP_SUSPECT_RMS_PX)
            or (own and (moved > SNAP_CHI2 or apart > SNAP_SIGMAS))):
        return dims, quads, camera, fits, uses
    warnings.extend(scratch)
    warnings.append(f"the refined edges fit a box {rms:.1f} px (RMS) from the clicks, the clicks "
                    f"alone one {alt_rms:.1f} px, more than the clicks' noise explains: the edges found "
                    "were not the box's (printed borders, a rounded edge's shading or background?), "
                    "so the clicks were used")
    why = EdgeUse("click", f"the box the edges fit sits {rms:.1f} px (RMS) from the clicks, the "
                           f"clicks' own {alt_rms:.1f} px; its size {apart:.1f} sigma from theirs: "
                           "more than click noise explains")
    return *alt, plain, {face: [why] * 4 for face in uses}


def fit_guard(spec: ScanSpec, marked: FaceQuads, model: FaceQuads, perspective: bool,
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

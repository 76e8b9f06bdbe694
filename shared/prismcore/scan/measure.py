"""Real dimensions of the prism from its refined face quads and the scale the user gave.

Two models:

* affine (the paper's): each face is taken as photographed squarely, so its size is its
  pixel size times a millimetres-per-pixel scale;
* perspective (needs all four corners of each face; in one photo the focal length may be
  fitted): the box's pose and proportions are fitted to the corners through a pinhole camera,
  and the scale fixes its size.

Each dimension carries a 1-sigma uncertainty: from the fit's covariance under click and edge
noise (perspective), or from the click noise and the obliqueness the square-on model ignores
(affine).

In one photo the second face may be the right side, the left side or the top
(`side_face`, see `prismcore.geometry.faces`): its quad is as photographed, and its depth edges run
horizontally in the photo for a side, vertically for a top.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from prismcore.geometry.evidence import box_edge_samples, undistort_evidence
from prismcore.geometry.lens import RadialDistortion, estimate_distortion
from prismcore.geometry.model_error import ROUNDING_RMS_MM, edge_shifts, model_error_cov, rounding_shifts
from prismcore.geometry.perspective import (
    NOISE_CLICK_PX,
    NOISE_LINE_PX,
    BoxFit,
    FaceEvidence,
    centre_depth,
    fit_box,
    fit_rectangle,
    project,
)
from prismcore.geometry.rounding import RadiusEstimate, estimate_edge_radius
from prismcore.spec import KnownEdge, MmPerPx, Pinhole, Scale

__all__ = ["PERSPECTIVE_SHARE", "Dimensions", "Obliqueness", "box_edge_radius", "camera_matrix",
           "measure_affine", "measure_perspective", "obliqueness", "perspective_cost", "quad_size_px"]

_MC_DRAWS = 256  # Monte Carlo draws of the click noise through the affine model
PERSPECTIVE_SHARE = 0.5
"""The square-on model's perspective error, as a share of the box's depth range over its distance
(`perspective_cost`). In one photo the parallelograms take every edge at the scale of the ones
marked: the height is read on the shared edge, the one nearest the camera, while a known width
or depth spans from it to a corner farther away, about half the box's depth range on average;
five points show no second edge of any direction, so that range is not seen, and the box's
extent in the photo over the focal length stands for it (a view showing two faces is about as
deep as it is wide)."""


@dataclass(frozen=True)
class Dimensions:
    """Width (X), height (Y) and depth (Z) of the prism, in `unit` ("mm" or "px").

    uncertainty : (sigma_width, sigma_height, sigma_depth) in `unit`, one standard deviation,
    or None when not estimated.
    """

    width: float
    height: float
    depth: float
    unit: str
    perspective: bool
    notes: tuple[str, ...] = field(default=())
    uncertainty: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Obliqueness:
    """How far a single photo's faces are from square-on, read from the quads (affine camera).

    front_deg, side_deg : angle between the front's (then the second face's) normal and the
        viewing direction, degrees
    foreshortening : (3,) float64, cos of the angle between the image plane and the X, Y, Z
        edges: the square-on model reads each edge this much short
    """

    front_deg: float
    side_deg: float
    foreshortening: np.ndarray


def quad_size_px(quad: np.ndarray) -> tuple[float, float]:
    """Mean lengths (px) of the horizontal and of the vertical sides of a TL, TR, BR, BL quad."""
    sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
    return float((sides[0] + sides[2]) / 2), float((sides[1] + sides[3]) / 2)


def camera_matrix(focal_px: float, principal: tuple[float, float]) -> np.ndarray:
    """Pinhole intrinsics K, shape (3, 3), for square pixels."""
    return np.array([[focal_px, 0, principal[0]], [0, focal_px, principal[1]], [0, 0, 1.0]])


def _three(values: np.ndarray) -> tuple[float, float, float]:
    """A (3,) array as three floats: (width, height, depth)."""
    a, b, c = (float(v) for v in values)
    return a, b, c


def _depth_edge(side: np.ndarray, side_face: str) -> np.ndarray:
    """The mean image vector (2,) of the side quad's edges that run along the depth (Z)."""
    edge: np.ndarray
    if side_face == "top":
        edge = (side[3] - side[0] + side[2] - side[1]) / 2
    else:
        edge = (side[1] - side[0] + side[2] - side[3]) / 2
    return edge


def _side_size_px(side: np.ndarray, side_face: str) -> tuple[float, float]:
    """(depth, other) mean side lengths (px) of the second face's quad."""
    across, down = quad_size_px(side)
    return (down, across) if side_face == "top" else (across, down)


def obliqueness(front: np.ndarray, side: np.ndarray, side_face: str = "right") -> Obliqueness | None:
    """The view direction of a single photo of a box, from its front and side quads.

    Under an affine camera the images a, b, c of the box's X, Y and Z edges satisfy
    a a^T / W^2 + b b^T / H^2 + c c^T / D^2 = s^2 I (the camera's rows are orthonormal): three
    equations for 1/W^2, 1/H^2, 1/D^2 up to s, hence the camera's rows and its viewing
    direction r3 = r1 x r2 in the box's frame.

    Parameters
    ----------
    front, side : ndarray, shape (4, 2)
        TL, TR, BR, BL image (x, y) px; the side face as photographed.
    side_face : {"right", "left", "top"}
        Where the second face lies (`side_deg` is then that face's angle).

    Returns
    -------
    Obliqueness or None
        None when the quads are not consistent with any view of a box (strong perspective or
        bad points).
    """
    a = (front[1] - front[0] + front[2] - front[3]) / 2
    b = (front[3] - front[0] + front[2] - front[1]) / 2
    c = _depth_edge(side, side_face)
    A = np.array([[a[0] ** 2, b[0] ** 2, c[0] ** 2],
                  [a[0] * a[1], b[0] * b[1], c[0] * c[1]],
                  [a[1] ** 2, b[1] ** 2, c[1] ** 2]])
    try:
        uvw = np.linalg.solve(A, [1.0, 0.0, 1.0])
    except np.linalg.LinAlgError:
        return None
    if not (np.isfinite(uvw).all() and (uvw > 0).all()):
        return None
    M = np.stack([a, b, c], axis=1) * np.sqrt(uvw)  # (2, 3), rows orthonormal up to noise
    r3 = np.cross(M[0], M[1])
    n = np.abs(r3) / np.linalg.norm(r3)
    normal = 1 if side_face == "top" else 0
    return Obliqueness(math.degrees(math.acos(min(1.0, n[2]))), math.degrees(math.acos(min(1.0, n[normal]))),
                       np.sqrt(np.clip(1 - n**2, 0.0, 1.0)))


def square_on_cost(view: Obliqueness, scale: Scale | None) -> np.ndarray:
    """Relative error (3,) of width, height, depth that the square-on model makes in this view.

    A known edge absorbs its own foreshortening (the others are off by the ratio); any other
    scale is taken in the face's plane, so each edge reads short by its foreshortening.
    """
    f = view.foreshortening
    if isinstance(scale, KnownEdge):
        ref = f[("width", "height", "depth").index(scale.edge)]
        cost: np.ndarray = np.abs(f / ref - 1)
        return cost
    cost = np.abs(f - 1)
    return cost


def _scales_affine(scale: Scale | None, sizes: dict[str, float], focal: float | None,
                   two_photo: bool) -> tuple[float | None, float | None, str]:
    front = side = None
    unit = "mm"
    if isinstance(scale, MmPerPx):
        front, side = scale.front, scale.side
    elif isinstance(scale, Pinhole):
        assert focal is not None  # the spec's validator demands it
        front = scale.distance_mm / focal
        side = scale.side_distance_mm / focal if scale.side_distance_mm else None
    elif isinstance(scale, KnownEdge):
        measured = {"width": sizes["w"], "height": sizes["h"], "depth": sizes["d"]}[scale.edge]
        if scale.edge == "depth":
            side = scale.length_mm / measured
        else:
            front = scale.length_mm / measured
    else:
        front, unit = 1.0, "px"
    if not two_photo:
        front = front or side
        side = side or front
    return front, side, unit


def _affine(front: np.ndarray, side: np.ndarray, scale: Scale | None, focal_px: float | None,
            two_photo: bool, side_face: str = "right") -> tuple[np.ndarray, str, list[str]]:
    w_px, h_px = quad_size_px(front)
    d_px, hs_px = _side_size_px(side, side_face)
    s_front, s_side, unit = _scales_affine(scale, {"w": w_px, "h": h_px, "d": d_px},
                                           focal_px, two_photo)
    notes = []
    # Two photos, one scale: the face height both photos show carries it across.
    if s_front is None and s_side is not None:
        s_front = s_side * hs_px / h_px
        notes.append("front scale derived from the side photo through the shared height")
    if s_side is None and s_front is not None:
        s_side = s_front * h_px / hs_px
        notes.append("side scale derived from the front photo through the shared height")
    assert s_front is not None and s_side is not None
    return np.array([w_px * s_front, h_px * s_front, d_px * s_side]), unit, notes


def _noise_sigma(fn: Callable[[np.ndarray, np.ndarray], np.ndarray], front: np.ndarray, side: np.ndarray,
                 noise_px: float) -> np.ndarray:
    """Standard deviation (3,) of fn(front, side) under independent corner noise (Monte Carlo,
    fixed seed: the same input gives the same sigma)."""
    rng = np.random.default_rng(0)
    draws = [fn(front + rng.normal(0, noise_px, front.shape), side + rng.normal(0, noise_px, side.shape))
             for _ in range(_MC_DRAWS)]
    sigma: np.ndarray = np.std(np.array(draws), axis=0)
    return sigma


def perspective_cost(front: np.ndarray, side: np.ndarray, focal_px: float) -> float:
    """Relative error (1 sigma) the square-on model may make on a dimension from the perspective
    it ignores: PERSPECTIVE_SHARE x the box's extent in the photo (the largest distance between
    two corners) over the focal length (px).

    The orthographic reading of the view (`obliqueness`) does not see it: perspective bends the
    very edges it reads (issue 37's five-point sample: front read 11° off square-on, the height
    17.6 % high, 8 sigma outside its stated ±; this gives 21 %).
    """
    corners = np.vstack([front, side]).astype(np.float64)
    span = float(np.max(np.linalg.norm(corners[:, None, :] - corners[None, :, :], axis=-1)))
    return PERSPECTIVE_SHARE * span / focal_px


def _oblique_cost(front: np.ndarray, side: np.ndarray, scale: Scale | None,
                  noise_px: float, side_face: str = "right") -> np.ndarray:
    """The square-on model's relative error (3,), a high (90th) percentile over the corner
    noise; views the noisy quads cannot explain count as the worst seen."""
    rng = np.random.default_rng(1)
    costs = []
    for _ in range(_MC_DRAWS):
        view = obliqueness(front + rng.normal(0, noise_px, front.shape),
                           side + rng.normal(0, noise_px, side.shape), side_face)
        costs.append(np.full(3, np.nan) if view is None else square_on_cost(view, scale))
    drawn = np.array(costs)
    if np.isnan(drawn).all():
        return np.ones(3)  # no view of a box fits these quads: nothing is known
    worst = np.nanmax(drawn, axis=0)
    drawn = np.where(np.isnan(drawn), worst, drawn)
    p90: np.ndarray = np.percentile(drawn, 90, axis=0)
    return p90


def measure_affine(front: np.ndarray, side: np.ndarray, scale: Scale | None, *,
                   focal_px: float | None, two_photo: bool, corner_noise_px: float = NOISE_CLICK_PX,
                   view: Obliqueness | None = None, clicked: tuple[np.ndarray, np.ndarray] | None = None,
                   side_face: str = "right", perspective_focal_px: float | None = None) -> Dimensions:
    """Dimensions with each face assumed square to the camera (the paper's model).

    Parameters
    ----------
    front, side : ndarray, shape (4, 2)
        Face quads, image (x, y) px.
    corner_noise_px : float
        1-sigma error of a corner, px, for the uncertainty.
    view : Obliqueness, optional
        The photo's estimated obliqueness (single photo): what the square-on model ignores is
        added to the uncertainty (read again from the noisy corners: a face seen nearly
        edge-on makes that reading itself unsure).
    clicked : (front, side) quads as clicked, optional
        When the refined edges moved the faces, the dimensions the clicks alone give: how far
        they disagree is added to the uncertainty (an edge taken from a printed line or a
        guessed corner shows up there).
    side_face : {"right", "left", "top"}
        Where the second face lies in one photo.
    perspective_focal_px : float, optional
        One photo: the focal length (px) to read the perspective the model ignores through
        (`perspective_cost`), added to each measured dimension's uncertainty (a given edge's
        stays 0).
    """
    dims, unit, notes = _affine(front, side, scale, focal_px, two_photo, side_face)
    sigma = _noise_sigma(lambda f, s: _affine(f, s, scale, focal_px, two_photo, side_face)[0], front,
                         side, corner_noise_px)
    if view is not None:
        sigma = np.hypot(sigma, _oblique_cost(front, side, scale, corner_noise_px, side_face) * dims)
    if clicked is not None:
        sigma = np.hypot(sigma, _affine(*clicked, scale, focal_px, two_photo, side_face)[0] - dims)
    if perspective_focal_px:
        measured = np.array([not (isinstance(scale, KnownEdge) and scale.edge == n)
                             for n in ("width", "height", "depth")])
        sigma = np.hypot(sigma, perspective_cost(front, side, perspective_focal_px) * dims * measured)
    return Dimensions(*_three(dims), unit, False, tuple(notes), _three(sigma))


def _scale_factor(scale: Scale | None, width: float, depth: float, z: float,
                  focal: float) -> tuple[float, str]:
    """Millimetres (or px at the front centre's depth) per model unit (the box's height)."""
    if isinstance(scale, Pinhole):
        return scale.distance_mm / z, "mm"
    if isinstance(scale, MmPerPx):
        return scale.front * focal / z, "mm"
    if isinstance(scale, KnownEdge):
        return scale.length_mm / {"width": width, "height": 1.0, "depth": depth}[scale.edge], "mm"
    return focal / z, "px"  # pixels at the front face centre's depth


def _box_dims(scale: Scale | None, v: np.ndarray) -> np.ndarray:
    width, depth, z, focal = v
    k = _scale_factor(scale, width, depth, z, focal)[0]
    return np.array([width * k, k, depth * k])


def _box_sigma(scale: Scale | None, fit: BoxFit) -> np.ndarray:
    v = np.array([fit.width, fit.depth, fit.centre_depth, fit.focal_px])
    G = np.zeros((3, 4))
    for k in range(4):
        h = 1e-6 * max(1.0, abs(v[k]))
        e = np.zeros(4)
        e[k] = h
        G[:, k] = (_box_dims(scale, v + e) - _box_dims(scale, v - e)) / (2 * h)
    sigma: np.ndarray = np.sqrt(np.clip(np.diag(G @ fit.shape_cov @ G.T), 0.0, None))
    return sigma


def measure_box(front: FaceEvidence, side: FaceEvidence, scale: Scale | None, *, K: np.ndarray,
                free_focal: bool = False, side_face: str = "right",
                lens_known: bool = False, image: np.ndarray | None = None) -> tuple[Dimensions, BoxFit]:
    """Dimensions of a box whose front and side share one photo, through a pinhole camera.

    The shooting distance (or mm-per-pixel, read as distance / focal) is the depth of the front
    face's centre along the optical axis.

    Unless the lens is known (its distortion already removed from the evidence), its radial
    distortion is read from how the box's edges bend (`lens.estimate_distortion`, a
    plumb-line estimate that stays at none while the bend is one the edges' noise explains) and
    removed from the evidence before the fit. The uncertainty adds to the click and edge noise
    what the model leaves out (`model_error.model_error_cov`): the estimate's error (the prior's,
    DISTORTION_PRIOR, when the edges say little), and edges rounded by an unknown radius
    (ROUNDING_RMS_MM; only when the scale is in mm, which says how large a millimetre is in the
    model).

    Parameters
    ----------
    K : ndarray, shape (3, 3)
        Intrinsics; with `free_focal` only the principal point is used and the focal is fitted.
    side_face : {"right", "left", "top"}
        Where the second face lies (see `perspective.fit_box`).
    lens_known : bool
        The evidence is already free of lens distortion (a calibrated camera's).
    image : ndarray, shape (H, W) or (H, W, 3), optional
        The photo: with a scale in mm, the edges' radius is read from the shading across the
        box's folds (`rounding.estimate_edge_radius`) and the silhouettes' inset it implies is
        taken out of the shape; its uncertainty replaces the prior ROUNDING_RMS_MM.

    Returns
    -------
    dimensions : Dimensions
        With the uncertainty from the fit's covariance and the model's errors.
    fit : BoxFit
        Its quads where the photo shows them (distortion put back); its `shape_cov` includes
        the model's errors.
    """
    principal = np.asarray(K[:2, 2], dtype=np.float64)
    if lens_known:
        lens = RadialDistortion(0.0, 0.0, principal)
    else:
        # The corner radius of an image whose centre is the principal point.
        radius = float(np.hypot(*(principal + 0.5)))
        # Read from how the box's long straight edges bend; the estimate's own error (the prior's
        # when the edges say little) is carried in the uncertainty.
        lens = estimate_distortion(box_edge_samples(front, side, side_face), principal, radius)
        if lens.kappa != 0.0:
            front, side = undistort_evidence(front, lens), undistort_evidence(side, lens)
    fit = fit_box(K, front, side, free_focal=free_focal, side_face=side_face)
    k, unit = _scale_factor(scale, fit.width, fit.depth, fit.centre_depth, fit.focal_px)
    shape = np.array([fit.width, fit.depth, fit.centre_depth, fit.focal_px])
    rounding = box_edge_radius(image, fit, lens, k) if unit == "mm" and image is not None else None
    notes: tuple[str, ...] = ()
    if rounding is None:
        silhouette_std = fold_radius = ROUNDING_RMS_MM / k if unit == "mm" else 0.0
    else:
        # The silhouettes lie inside the sharp outline by an inset the radius sets: the fit's
        # linear response to that shift of its edge lines is taken out of the shape.
        radius = rounding.radius_mm / k
        if radius > 0 and fit.influence is not None:
            # What the rounding did to the lines: silhouettes moved in by the inset, folds
            # moved from the sharp edge to where the shading ramp put them.
            moved = rounding_shifts(fit, front, side, radius, side_face=side_face)[0]
            folds = [(mid / k, -offset) for mid, offset in rounding.fold_offsets]
            moved += edge_shifts(fit, front, side, folds, side_face=side_face)
            shape = shape - fit.influence @ moved
        silhouette_std = rounding.std_mm / k
        fold_radius = (rounding.radius_mm + rounding.std_mm) / k
        notes = (f"edges rounded {rounding.radius_mm:.1f} ± {rounding.std_mm:.1f} mm (read from the "
                 "shading at the folds): the silhouettes' inset corrected",)
    cov = fit.shape_cov + model_error_cov(fit, front, side, side_face=side_face,
                                          distortion_std=lens.kappa_std, rounding_radius=silhouette_std,
                                          fold_radius=fold_radius)
    focal_std = None if fit.focal_std_px is None else float(np.sqrt(max(cov[3, 3], 0.0)))
    fit = replace(fit, width=float(shape[0]), depth=float(shape[1]), focal_px=float(shape[3]), shape_cov=cov,
                  focal_std_px=focal_std, front_quad=lens.distort(fit.front_quad),
                  side_quad=lens.distort(fit.side_quad), lens=lens)
    dims = _box_dims(scale, shape)
    sigma = _box_sigma(scale, fit)
    return Dimensions(*_three(dims), unit, True, notes, _three(sigma)), fit


def box_edge_radius(image: np.ndarray, fit: BoxFit, lens: RadialDistortion, mm_per_unit: float
                    ) -> RadiusEstimate | None:
    """The edges' radius read from the photo through the fitted box (model units scaled to mm):
    `rounding.estimate_edge_radius` with the box's projection (pose, focal length, principal
    point and `lens`'s distortion) and its camera centre. A view of a joint fit reads it the same
    way (`multiview.model_sigma`)."""
    assert fit.principal is not None
    K = camera_matrix(fit.focal_px, (float(fit.principal[0]), float(fit.principal[1])))
    R = cv2.Rodrigues(np.asarray(fit.rvec, dtype=np.float64))[0]

    def to_image(world_mm: np.ndarray) -> np.ndarray:
        return lens.distort(project(K, fit.rvec, fit.tvec, world_mm / mm_per_unit))

    return estimate_edge_radius(image, to_image, np.array([fit.width, 1.0, fit.depth]) * mm_per_unit,
                                -R.T @ fit.tvec * mm_per_unit)


def measure_perspective(front: FaceEvidence, side: FaceEvidence, scale: Scale | None, *,
                        K_front: np.ndarray, K_side: np.ndarray, two_photo: bool,
                        side_face: str = "right") -> tuple[Dimensions, np.ndarray, np.ndarray]:
    """Dimensions with perspective corrected through a pinhole camera of known focal length.

    The shooting distance (or mm-per-pixel, read as distance / focal) is the depth of the front
    face's centre along the optical axis.

    Returns
    -------
    dimensions : Dimensions
    front_quad, side_quad : ndarray, shape (4, 2)
        The faces' corners as the fitted model projects them.
    """
    if not two_photo:
        measured, fit = measure_box(front, side, scale, K=K_front, side_face=side_face)
        return measured, fit.front_quad, fit.side_quad

    def two_rectangles(
        f_corners: np.ndarray, s_corners: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f_ev = FaceEvidence(f_corners, front.clicked, front.lines)
        s_ev = FaceEvidence(s_corners, side.clicked, side.lines)
        width, rvec, tvec, front_quad = fit_rectangle(K_front, f_ev)
        depth, _, _, side_quad = fit_rectangle(K_side, s_ev)
        z = centre_depth(rvec, tvec, width)
        return _box_dims(scale, np.array([width, depth, z, float(K_front[0, 0])])), front_quad, side_quad

    dims, front_quad, side_quad = two_rectangles(front.corners, side.corners)
    unit = "px" if scale is None else "mm"
    # Two independent rectangle fits: their relative noise is that of the side lengths the
    # fitted lines give, which the affine model's Monte Carlo measures.
    focal = float(K_front[0, 0])
    flat = _affine(front.corners, side.corners, scale, focal, True)[0]
    rel = _noise_sigma(lambda f, s: _affine(f, s, scale, focal, True)[0], front.corners,
                       side.corners, NOISE_LINE_PX) / np.maximum(flat, 1e-12)
    return (Dimensions(*_three(dims), unit, True, (), _three(rel * dims)),
            front_quad, side_quad)

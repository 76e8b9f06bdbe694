"""What the pinhole box model leaves out, as covariance: lens distortion left in the points and
rounded edges, each a systematic shift of the data of known shape and uncertain size carried to
the shape by the fit's linear response (`BoxFit.influence`).
"""

from __future__ import annotations

import cv2
import numpy as np

from prismcore.geometry.box_model import FRONT_IDX, SECOND_FACES, camera_matrix
from prismcore.geometry.perspective import (
    SIGMA_CLICK_PX,
    SIGMA_LINE_PX,
    BoxFit,
    FaceEvidence,
    FaceTerms,
    line_terms,
    project,
)

__all__ = ["FOLD_FRACTION", "ROUNDING_RMS_MM", "edge_shifts", "model_error_cov", "rounding_shifts"]

ROUNDING_RMS_MM = 1.5
"""RMS radius (mm) of a box's rounded edges when nothing says it (folded carton, moulded and
machined parts: 0-2.5 mm); a sharp box has 0. Its silhouette lies inside the sharp outline."""
FOLD_FRACTION = 0.5
"""Where an edge detector finds a rounded fold (both faces seen): anywhere on the shading ramp
the rounding makes, which spans about the radius on either face; 1-sigma, in radii."""


def model_error_cov(fit: BoxFit, front: FaceEvidence, side: FaceEvidence, *, side_face: str = "right",
                    distortion_std: float = 0.0, rounding_radius: float = 0.0,
                    fold_radius: float | None = None) -> np.ndarray:
    """Covariance (4, 4) of (width, depth, z, focal_px) from what the pinhole box model leaves out.

    Each effect is a systematic shift of the data of known shape and uncertain size, carried to
    the shape by the fit's linear response (`BoxFit.influence`), so that whatever the pose and
    the focal length absorb costs nothing:

    * lens distortion left in the points (`distortion_std`, px^-2, the 1-sigma of kappa in
      `RadialDistortion` about what was removed): every corner moves by
      delta (p - c) |p - c|^2, its clicks with it, and each edge line with its end points;
    * rounded edges (`rounding_radius`, the radius in the model's units, height 1, 1-sigma):
      a silhouette edge (the face beyond it turned away) appears where the camera's ray grazes
      the rounded edge, which meets the face's plane at r (sin a + cos a - 1) / sin a inside
      the sharp edge (a the ray's angle to the face's plane across the edge). All silhouettes
      of a box move together (one radius). A fold edge (both faces seen) is found somewhere on
      the shading ramp the rounding makes: FOLD_FRACTION radii (of `fold_radius`, default
      `rounding_radius`), independently per edge.
    """
    if fit.influence is None or fit.principal is None:
        return np.zeros((4, 4))
    second = SECOND_FACES[side_face]
    faces: FaceTerms = [(front, FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]
    K = camera_matrix(fit.focal_px, fit.principal)
    model = second.corners(np.array([fit.width, fit.depth]))
    image = project(K, fit.rvec, fit.tvec, model)
    rows = line_terms(faces)
    n_lines = len(rows)
    n = fit.influence.shape[1]
    patterns: list[np.ndarray] = []
    if distortion_std > 0:
        d = image - fit.principal
        move = distortion_std * d * (d**2).sum(axis=1, keepdims=True)
        dr = np.zeros(n)
        for k, (_, _, line, corner) in enumerate(rows):
            dr[k] = -float(line[:2] @ move[corner]) / SIGMA_LINE_PX
        dr[n_lines:] = -np.concatenate([move[list(idx)].ravel() for _, idx, _ in faces]) / SIGMA_CLICK_PX
        patterns.append(dr)
    if rounding_radius > 0:
        patterns.append(rounding_shifts(fit, front, side, rounding_radius, side_face=side_face)[0])
    fold = rounding_radius if fold_radius is None else fold_radius
    if fold > 0:
        patterns += rounding_shifts(fit, front, side, FOLD_FRACTION * fold, side_face=side_face)[1]
    cov = np.zeros((4, 4))
    for dr in patterns:
        dx = fit.influence @ dr
        cov += np.outer(dx, dx)
    return cov


def rounding_shifts(fit: BoxFit, front: FaceEvidence, side: FaceEvidence, radius: float, *,
                    side_face: str = "right") -> tuple[np.ndarray, list[np.ndarray]]:
    """How edges rounded with `radius` (model units, height 1) move the fit's whitened residuals.

    A silhouette edge (the face beyond it turned away) appears where the camera's ray grazes the
    rounded edge, which meets the face's plane at r (sin a + cos a - 1) / sin a inside the sharp
    edge (a the ray's angle to the face's plane across the edge); a fold edge (both faces seen)
    is moved in by `radius` itself. The clicks do not move (they mark the corners).

    Returns
    -------
    silhouettes : ndarray, shape (n_residuals,)
        All silhouettes together (one radius moves them all).
    folds : list of ndarray, shape (n_residuals,)
        One pattern per fold edge.
    """
    n = 0 if fit.influence is None else fit.influence.shape[1]
    if fit.principal is None or n == 0:
        return np.zeros(n), []
    second = SECOND_FACES[side_face]
    faces: FaceTerms = [(front, FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]
    K = camera_matrix(fit.focal_px, fit.principal)
    model = second.corners(np.array([fit.width, fit.depth]))
    image = project(K, fit.rvec, fit.tvec, model)
    R = cv2.Rodrigues(np.asarray(fit.rvec, dtype=np.float64))[0]
    camera_centre = -R.T @ fit.tvec
    box_centre = np.array([fit.width, 1.0, fit.depth]) / 2
    silhouettes = np.zeros(n)
    folds: dict[tuple[int, int], np.ndarray] = {}
    for k, (f, s, line, corner) in enumerate(line_terms(faces)):
        quad = model[list(faces[f][1])]
        centre = quad.mean(axis=0)
        normal = (centre - box_centre) / np.linalg.norm(centre - box_centre)
        mid = (quad[s] + quad[(s + 1) % 4]) / 2
        out = (mid - centre) / np.linalg.norm(mid - centre)
        ray = camera_centre - mid
        dm, dn = float(ray @ out), float(ray @ normal)
        silhouette = dm < 0 and dn > 0
        if silhouette:
            a = np.arctan2(dn, -dm)
            inset = radius * (np.sin(a) + np.cos(a) - 1) / np.sin(a)
        else:
            inset = radius
        moved = project(K, fit.rvec, fit.tvec, (model[corner] - inset * out)[None])[0]
        shift = -float(line[:2] @ (moved - image[corner])) / SIGMA_LINE_PX
        if silhouette:
            silhouettes[k] = shift
        else:
            folds.setdefault((f, s), np.zeros(n))[k] = shift
    return silhouettes, list(folds.values())


def edge_shifts(fit: BoxFit, front: FaceEvidence, side: FaceEvidence,
                moves: list[tuple[np.ndarray, np.ndarray]], *, side_face: str = "right") -> np.ndarray:
    """How moving some of the box's edge lines in the image changes the fit's whitened residuals.

    moves : per edge, its model midpoint (3,) (height 1) and the image vector (2,) px by which
        its fitted line moves; an edge the fit has no line for is skipped.

    Returns
    -------
    ndarray, shape (n_residuals,)
    """
    n = 0 if fit.influence is None else fit.influence.shape[1]
    second = SECOND_FACES[side_face]
    faces: FaceTerms = [(front, FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]
    model = second.corners(np.array([fit.width, fit.depth]))
    dr = np.zeros(n)
    for k, (f, s, line, _) in enumerate(line_terms(faces)):
        idx = faces[f][1]
        mid = (model[idx[s]] + model[idx[(s + 1) % 4]]) / 2
        for where, vector in moves:
            if np.linalg.norm(where - mid) < 1e-6 * max(1.0, fit.width, fit.depth):
                dr[k] = -float(line[:2] @ vector) / SIGMA_LINE_PX
    return dr

"""The box fit's closed-form Jacobian against central differences of its own residuals, over
random boxes, poses, lines and clicks, each second face, a fixed and a free focal length: the
fits (one photo's and the joint one's) trust it instead of the solver's finite differences."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from prismcore.geometry.box_model import FRONT_IDX, SECOND_FACES, camera_matrix
from prismcore.geometry.perspective import (
    FaceEvidence,
    residual_and_jacobian,
)


def _evidence(rng: np.random.Generator, quad: np.ndarray) -> FaceEvidence:
    lines = []
    for s in range(4):
        if rng.uniform() < 0.2:
            lines.append(None)  # an edge not found
            continue
        a, b = quad[s] + rng.normal(0, 2, 2), quad[(s + 1) % 4] + rng.normal(0, 2, 2)
        n = np.array([a[1] - b[1], b[0] - a[0]])
        n /= np.linalg.norm(n)
        lines.append(np.array([n[0], n[1], -n @ a]))
    return FaceEvidence(corners=quad, clicked=quad + rng.normal(0, 3, (4, 2)), lines=tuple(lines))


@pytest.mark.parametrize("side_face", ["right", "left", "top"])
@pytest.mark.parametrize("free_focal", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_closed_form_jacobian_matches_central_differences(side_face, free_focal, seed):
    rng = np.random.default_rng([seed, 7])
    principal = np.array([640.0, 512.0])
    second = SECOND_FACES[side_face]
    shape = rng.uniform(0.4, 2.0, 2)
    x = np.r_[rng.normal(0, 0.25, 3), rng.uniform(-0.4, 0.4, 2), rng.uniform(3, 6), shape]
    f = rng.uniform(800, 2000)
    if free_focal:
        x = np.r_[x, np.log(f)]

    def intrinsics(v: np.ndarray) -> np.ndarray:
        return camera_matrix(float(np.exp(v[8])) if free_focal else f, principal)

    # evidence drawn near the box as projected, so every term is of a typical size
    corners = second.corners(shape)
    pts = cv2.projectPoints(corners, x[:3], x[3:6], intrinsics(x), None)[0].reshape(-1, 2)
    front = _evidence(rng, pts[list(FRONT_IDX)])
    side = _evidence(rng, pts[list(second.idx)])
    faces = [(front, FRONT_IDX, (0, 1, 2, 3)), (side, second.idx, second.sides)]
    residual, jac = residual_and_jacobian(intrinsics, second.corners, 2, faces, log_focal=free_focal)

    J = jac(x)
    numeric = np.empty_like(J)
    for k in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[k]))
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        numeric[:, k] = (residual(up) - residual(down)) / (2 * h)
    assert J.shape == (len(residual(x)), len(x))
    np.testing.assert_allclose(J, numeric, rtol=1e-4, atol=1e-4 * np.abs(numeric).max())

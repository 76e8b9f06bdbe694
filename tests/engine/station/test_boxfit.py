"""The box fit's geometry: the folds it pulls to the photo's edges are those between the faces the
camera sees (`visible_faces`, also what the seven points and the side count use)."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.station.boxfit import (
    _EDGES,
    _folds,
    _hull,
    _jacobian,
    _Problem,
    _residuals,
    box_corners,
    fit_outline_box,
    project,
    visible_faces,
)


def _folds_of_faces(corners: np.ndarray, centre: np.ndarray) -> set[tuple[int, int]]:
    """The oracle: box edges shared by two faces the camera sees."""
    seen = [set(idx) for idx, _ in visible_faces(corners, centre).values()]
    return {(i, j) for i, j in _EDGES if sum({i, j} <= f for f in seen) == 2}


def test_the_fits_folds_are_the_edges_between_two_seen_faces_over_random_boxes() -> None:
    rng = np.random.default_rng(0)
    for _ in range(2000):
        params = np.array([*rng.uniform(-300, 300, 2), rng.uniform(0, np.pi),
                           *np.log(rng.uniform(20, 400, 3))])
        centre = np.array([*rng.uniform(-900, 900, 2), -rng.uniform(30, 1500)])
        assert set(_folds(params, centre)) == _folds_of_faces(box_corners(params), centre), (params, centre)


def test_visible_faces_gives_the_seen_faces_areas_in_the_image() -> None:
    params = np.array([0.0, 0.0, 0.3, np.log(120), np.log(80), np.log(60)])
    corners = box_corners(params)
    centre = np.array([100.0, -700.0, -600.0])  # above, in front of the s0 side (y < 0)
    image = corners[:, :2] + corners[:, 2:] * (0.5, 0.8)  # any oblique drawing: the areas are its polygons'
    faces = visible_faces(corners, centre, image)
    assert "top" in faces and "s0" in faces and "s2" not in faces
    assert all(area > 0 for _, area in faces.values())
    assert all(area == 0 for _, area in visible_faces(corners, centre).values())


def _problem(rng: np.random.Generator, noise_px: float = 1.5) -> tuple[np.ndarray, _Problem]:
    """A box seen from above and in front, its outline a perturbed copy of its own silhouette, with
    smooth distance maps (so the bilinear lookups have a gradient to compare)."""
    K = np.array([[1400.0, 0, 640], [0, 1400.0, 512], [0, 0, 1]])
    tilt = np.radians(rng.uniform(35, 55))
    R = np.array([[1.0, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    t = np.array([0.0, 0.0, rng.uniform(700, 1000)])
    params = np.array([*rng.uniform(-40, 40, 2), rng.uniform(0, np.pi), *np.log(rng.uniform(60, 200, 3))])
    pts = project(box_corners(params), K, R, t)
    hull = pts[_hull(pts)]
    s = np.linspace(0, 1, 25, endpoint=False)[:, None]
    outline = np.concatenate([a + s * (b - a) for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True)])
    outline = outline + rng.normal(0, noise_px, outline.shape)
    yy, xx = np.mgrid[0:1024, 0:1280].astype(np.float32)
    smooth = (np.sin(xx / 37.0) * np.cos(yy / 23.0) * 3).astype(np.float32)  # any smooth map will do
    p = _Problem(outline, smooth, np.zeros(2), K, R, t, -R.T @ t, smooth, np.zeros(2),
                 vertex_weight=0.7, fold_weight=0.6)
    return params + rng.normal(0, [3, 3, 0.05, 0.05, 0.05, 0.05]), p


def test_the_fits_jacobian_matches_central_differences_over_random_boxes() -> None:
    """The closed-form Jacobian (which reuses the residuals' last nearest edges) against central
    differences of the residuals, asked in both orders: after the residuals at the same point and
    at another point first (the reuse must not hand it stale geometry)."""
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(40):
        x, p = _problem(rng)
        numeric = np.empty((len(_residuals(x, p)), 6))
        for j in range(6):
            step = np.zeros(6)
            step[j] = 1e-6
            numeric[:, j] = (_residuals(x + step, p) - _residuals(x - step, p)) / 2e-6
        # the residuals were last evaluated elsewhere (x - step): the Jacobian must not reuse them
        stale_first = _jacobian(x, p)
        _residuals(x, p)
        after = _jacobian(x, p)
        np.testing.assert_array_equal(stale_first, after)
        # A row agrees to 0.1 %; rows whose nearest edge, hull or lookup pixel changes within the
        # step have no derivative there, and are few.
        agree = np.abs(numeric - after).max(axis=1) <= 1e-3 * (1 + np.abs(numeric).max(axis=1))
        n = len(p.outline)
        blocks = {"outline": np.arange(n), "hull vertices": n + np.flatnonzero(after[n:n + 8].any(axis=1)),
                  "folds": n + 8 + np.flatnonzero(after[n + 8:].any(axis=1))}
        for name, rows in blocks.items():
            assert len(rows) and agree[rows].mean() > 0.85, (name, rows[~agree[rows]])
        checked += int(agree.sum())
    assert checked > 40 * 100


@pytest.mark.parametrize("seed", range(4))
def test_a_fit_that_leaves_much_of_the_outline_out_widens_its_sigma(seed: int) -> None:
    """The middle of two sides' outline pulled 10 px inside the box (a face merged with the
    support, found in part), a quarter of the outline: the robust fit leaves those points out as
    outliers, and its sigma must then say the box is not what the outline says, not the noise of
    the rest (that sigma once missed a height read 4.3 mm for 20 mm). The oracle: the same box's
    fit on the whole outline."""
    rng = np.random.default_rng(seed)
    _, p = _problem(rng, noise_px=0.3)
    clean = p.outline
    dented = clean.copy()
    centre = clean.mean(axis=0)
    middle = np.r_[3:22, 53:72]  # 25 points a side: the middle of the first side and the third
    inward = centre - dented[middle]
    dented[middle] += 10 * inward / np.linalg.norm(inward, axis=1, keepdims=True)
    whole = fit_outline_box(clean, p.K, p.R, p.t)
    dent = fit_outline_box(dented, p.K, p.R, p.t)
    assert min(np.array(dent.sigma_mm()) / np.array(whole.sigma_mm())) > 3
    # and the stretch left out is still said (by the robust sigma, not the widened one)
    assert dent.missing_fraction > 0.08 > whole.missing_fraction


@pytest.mark.parametrize("seed", range(4))
def test_a_fit_whose_sides_disagree_widens_its_sigma_and_a_clean_one_does_not(seed: int) -> None:
    """One side of the silhouette pushed 6 px out along its whole length (a shadow taken for the
    part): the sides no longer agree on one box, and the fit's sigma must say so (the leave-one-
    side-out spread, or a rival box fitting as well), where the same box's clean outline keeps
    its sigma near the outline's noise."""
    rng = np.random.default_rng(100 + seed)
    _, p = _problem(rng, noise_px=0.3)
    clean = p.outline
    whole = fit_outline_box(clean, p.K, p.R, p.t)
    pushed = clean.copy()
    side = np.r_[0:25]
    outward = pushed[side] - clean.mean(axis=0)
    pushed[side] += 6 * outward / np.linalg.norm(outward, axis=1, keepdims=True)
    off = fit_outline_box(pushed, p.K, p.R, p.t)
    err = np.abs(np.exp(off.params[3:]) - np.exp(whole.params[3:]))
    # the error the push made is within 3 sigma of the pushed fit, in every size
    assert np.all(err <= 3 * np.array(off.sigma_mm()) + 0.05 * np.exp(whole.params[3:]).min())
    assert max(whole.ambiguity_mm) < 0.5 * min(np.exp(whole.params[3:]))

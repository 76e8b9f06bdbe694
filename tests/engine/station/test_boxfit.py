"""The box fit's geometry: the folds it pulls to the photo's edges are those between the faces the
camera sees (`visible_faces`, also what the seven points and the side count use)."""

from __future__ import annotations

import numpy as np

from prismcore.station.boxfit import _EDGES, _folds, box_corners, visible_faces


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

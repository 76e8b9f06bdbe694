"""prismpbr, the physically based scene generator: its geometry checked against independent
oracles (OpenCV's board detector on its renders, the rounded box's own definition), its sets kept
apart. Renders are small (few samples, a reduced photo) and go to a temporary cache."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from prismcore.station.board import find_board_corners
from prismpbr import DEVELOPMENT, REPORT, handheld_scene, render_scene, station_scenes
from prismpbr.meshes import rounded_box
from prismpbr.sets import handheld_seeds, station_seeds

SMALL = replace(DEVELOPMENT, name="test", image_size=(640, 480), spp=4)


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PRISM_PBR_CACHE", str(tmp_path))


@pytest.mark.parametrize("size, radius", [((40.0, 20.0, 10.0), 2.0), ((100.0, 60.0, 30.0), 0.5),
                                          ((15.0, 15.0, 15.0), 3.0), ((50.0, 30.0, 20.0), 0.0)])
def test_the_rounded_box_has_its_size_and_its_radius(size, radius) -> None:
    v, n, uv, tris = rounded_box(size, radius)
    half = np.array(size) / 2
    assert np.allclose(v.min(axis=0), -half, atol=1e-4) and np.allclose(v.max(axis=0), half, atol=1e-4)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    # every vertex lies on the rounded surface: at the radius from the inner box, or on a face
    inner = half - radius
    d = np.linalg.norm(v - np.clip(v, -inner, inner), axis=1)
    on_face = np.isclose(np.abs(v), half, atol=1e-4).any(axis=1)
    assert np.all(np.isclose(d, radius, atol=1e-3) | on_face)
    assert uv.min() >= 0 and uv.max() <= 1 and tris.max() < len(v)
    # the triangles face outwards: their normals agree with the vertices'
    a, b, c = v[tris[:, 0]], v[tris[:, 1]], v[tris[:, 2]]
    face_n = np.cross(b - a, c - a)
    big = np.linalg.norm(face_n, axis=1) > 1e-6
    assert np.mean(np.einsum("ij,ij->i", face_n[big], n[tris[big, 0]]) > 0) > 0.99


@pytest.mark.parametrize("seed", [11, 12])
def test_the_board_is_rendered_where_the_scenes_camera_projects_it(seed) -> None:
    """The oracle is OpenCV's ChArUco detector: the corners it finds in the render lie where the
    scene's camera (intrinsics, distortion, pose) puts the board's corners."""
    plate, _ = station_scenes(seed, 0, SMALL)
    view = find_board_corners(render_scene(plate), plate.board)
    assert view is not None and len(view) >= 12
    err = np.linalg.norm(view.image_points.reshape(-1, 2) - plate.camera.project(view.object_points), axis=1)
    # (at 1024x768 and 8 samples a pixel the median is 0.11 px; here the render's noise shows)
    assert np.median(err) < 0.6 and err.max() < 2.0


def test_a_part_is_rendered_inside_its_projected_outline() -> None:
    """Against the empty support under the same light: the part's projected outline holds what
    changed; far from it (beyond its shadow's reach) the photo is the support's, once the camera's
    auto exposure (a gain per channel) is taken out."""
    import cv2

    plate, photos = station_scenes(13, 1, replace(SMALL, materials=(1, 0, 0, 0, 0, 0)))
    empty, photo = render_scene(plate).astype(float), render_scene(photos[0]).astype(float)
    part = photos[0].part
    assert part is not None
    outline = cv2.convexHull(photos[0].camera.project(part.corners()).astype(np.float32)).astype(np.int32)
    inside = np.zeros(photo.shape[:2], np.uint8)
    cv2.fillConvexPoly(inside, outline, 1)
    far = cv2.dilate(inside, np.ones((121, 121), np.uint8)) == 0
    gain = np.median(photo[far] + 1, axis=0) / np.median(empty[far] + 1, axis=0)
    diff = np.linalg.norm(photo - empty * gain, axis=2)
    assert np.median(diff[inside > 0]) > 3 * np.median(diff[far])
    assert np.median(diff[far]) < 30  # two renders of 4 samples a pixel: their noise


def test_the_development_and_report_sets_share_no_seed_and_differ_in_their_settings() -> None:
    assert not set(station_seeds(DEVELOPMENT, 100)) & set(station_seeds(REPORT, 100))
    assert not set(handheld_seeds(DEVELOPMENT, 100)) & set(handheld_seeds(REPORT, 100))
    assert replace(REPORT, name=DEVELOPMENT.name) != DEVELOPMENT


def test_a_hand_held_scene_shows_the_whole_part_and_enough_of_the_board() -> None:
    for seed in handheld_seeds(SMALL, 5):
        sc = handheld_scene(seed, SMALL)
        assert sc.part is not None
        p = sc.camera.project(sc.part.corners())
        w, h = sc.camera.size
        assert (p >= 0).all() and (p[:, 0] < w).all() and (p[:, 1] < h).all()


def test_renders_are_cached_and_the_same_scene_renders_the_same() -> None:
    plate, _ = station_scenes(14, 0, replace(SMALL, image_size=(320, 240)))
    first = render_scene(plate)
    again = render_scene(plate)
    assert np.array_equal(first, again)
    fresh = render_scene(plate, cache=False)
    # Mitsuba's threads share out the image's blocks differently run to run: the noise differs
    assert np.corrcoef(fresh.ravel(), first.ravel())[0, 1] > 0.95

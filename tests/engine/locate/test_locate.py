"""Zero-click search (prismcore.locate.search) on rendered scenes whose box corners are known.

The truth is the renderer's projection of the box's eight corners (prismsynth.scenes), not
anything the search computes; the search may name the faces its own way, so each found point
is checked against the nearest true corner and the seven must land on six distinct corners.

The search makes discrete choices (a region closes or leaks, a face is found at one edge
sensitivity or not) that a one-grey-level change can flip on one scene; so the accuracy tests
assert rates over many scenes with a margin below what `benchmarks/zero_click.py` measures,
and that nothing wrong is ever accepted unflagged, never one seed's outcome. A refusal's reason
is one of `REFUSALS`. `test_locate_perturbed.py` measures how often a decision flips.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from prismcore import InputError, ScanSpec
from prismcore.locate.search import CONFIDENCE_MIN, find_points, resolve_points
from prismcore.locate.second_face import propose_neighbours
from prismsynth import Box, render_front_view
from prismsynth.scenes import clutter_scene, empty_scene, two_box_scene

REFUSALS = ("no box found", "only one face visible", "2 candidate boxes", "the box found is uncertain",
            "the box found does not fit a box model")
"""What a refusal may say (the README and the API's docs list them)."""


def _worst(found, corners: np.ndarray) -> tuple[float, int]:
    """Worst distance (px) of a found point to its nearest true corner; corners hit."""
    hit, worst = set(), 0.0
    for xy in found.points.as_dict().values():
        d = np.linalg.norm(corners - np.asarray(xy), axis=1)
        hit.add(int(np.argmin(d)))
        worst = max(worst, float(d.min()))
    return worst, len(hit)


@pytest.fixture(scope="module")
def two_boxes():
    return two_box_scene(0)


WRONG_PX = 10.0  # farther than this from the true corners, an accepted box is another box


@dataclass(frozen=True)
class Outcomes:
    right: list[int]  # found, every point within the tolerance of a true corner, six corners
    wrong: list[int]  # found and accepted, but another box (not six corners, or > WRONG_PX off)
    imprecise: list[int]  # the box, found less precisely than the tolerance (counted as not right)
    refused: dict[int, str]


def _outcomes(seeds: Iterable[int], tol_px: float) -> Outcomes:
    right, wrong, imprecise, refused = [], [], [], {}
    for seed in seeds:
        scene = clutter_scene(seed)
        found = find_points(scene.image)
        if not found.ok:
            assert found.reason.startswith(REFUSALS), (seed, found.reason)
            refused[seed] = found.reason
            continue
        assert found.confidence >= CONFIDENCE_MIN and found.side_face in ("right", "left", "top")
        worst, corners = _worst(found, scene.vertices_px)
        if corners != 6 or worst > WRONG_PX:
            wrong.append(seed)
        else:
            (right if worst <= tol_px else imprecise).append(seed)
    return Outcomes(right, wrong, imprecise, refused)


@pytest.fixture(scope="module")
def clutter_0_to_39() -> Outcomes:
    return _outcomes(range(40), 3.0)


def test_finds_the_points_within_3_px_in_most_cluttered_scenes(clutter_0_to_39):
    # benchmarks/zero_click.py: 80 % of seeds 0-199, 78 % of 200-399; here 32 of 40 measured.
    assert len(clutter_0_to_39.right) >= 26, clutter_0_to_39  # 65 %


def test_never_accepts_a_wrong_box_in_clutter(clutter_0_to_39):
    assert clutter_0_to_39.wrong == [], clutter_0_to_39


def test_refuses_an_empty_background():
    found = find_points(empty_scene(0))
    assert not found.ok
    assert found.reason.startswith(("no box found", "only one face visible")), found.reason
    assert found.points is None
    assert found.timings_ms["search_cpu"] > 0  # the benchmark's load-independent figure


def test_refuses_one_face():
    scene = render_front_view(Box(120, 90, 70))
    found = find_points(scene.image)
    assert not found.ok
    assert found.reason.startswith("only one face visible")


def test_two_equal_boxes_need_a_hint(two_boxes):
    image, _ = two_boxes
    found = find_points(image)
    assert not found.ok
    assert found.reason.startswith("2 candidate boxes")
    assert found.confidence < CONFIDENCE_MIN


@pytest.mark.parametrize("which", [0, 1])
def test_hint_and_roi_choose_the_box(two_boxes, which):
    image, corners = two_boxes
    box = corners[which]
    by_hint = find_points(image, hint=tuple(box.mean(axis=0)))
    lo, hi = box.min(axis=0) - 40, box.max(axis=0) + 40
    by_roi = find_points(image, roi=(lo[0], lo[1], hi[0], hi[1]))
    for found in (by_hint, by_roi):
        assert found.ok, found.reason
        worst, hit = _worst(found, box)
        assert worst <= 3.0 and hit == 6


def test_hint_away_from_any_box(two_boxes):
    image, _ = two_boxes
    found = find_points(image, hint=(640.0, 20.0))
    assert not found.ok and found.reason.startswith("no box found around the hint")


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"hint": (5000.0, 3.0)}, "outside"),
    ({"roi": (100.0, 100.0, 50.0, 400.0)}, "X0 < X1"),
    ({"roi": (0.0, 0.0, 10.0, 10.0)}, "16x16"),
])
def test_bad_hint_or_roi_is_an_input_error(two_boxes, kwargs, words):
    image, _ = two_boxes
    with pytest.raises(InputError, match=words):
        find_points(image, **kwargs)


def test_spec_points_auto_resolves_to_the_found_points(two_boxes):
    image, corners = two_boxes
    hint = [float(v) for v in corners[1].mean(axis=0)]
    spec = ScanSpec.model_validate({"image": "x.png", "points": "auto", "auto_points": {"hint": hint}})
    assert spec.points is None and spec.auto_points is not None
    resolved, found = resolve_points(spec, image)
    assert resolved.points == found.points and resolved.auto_points is None
    assert resolved.side_face == found.side_face
    assert found.report()["points_source"] == "auto"
    with pytest.raises(InputError, match="2 candidate boxes"):
        resolve_points(spec.model_copy(update={"auto_points": spec.auto_points.model_copy(
            update={"hint": None})}), image)


def test_spec_points_auto_is_for_one_photo():
    with pytest.raises(ValueError, match="one photo"):
        ScanSpec.model_validate({"image": "x.png", "points": "auto", "side_image": "y.png"})


# Scenes each once refused, by cause; the search was mended for each. As a group they must stay
# found (one seed's discrete choice may flip on another machine, so with a margin).
ONCE_REFUSED = {
    # A face found twice: both faces are found at two edge sensitivities, a few px apart; the
    # two copies of one face once passed for a pair sharing an edge, made a false third face
    # with the other, and the true pair was never tried ("only one face visible").
    60: "face-found-twice", 105: "face-found-twice",
    # A side with weak edges: its edge is found on only about half its profiles (it was refused
    # at 0.38); the box model still meets every fitted edge within 0.1 px.
    41: "weak-side",
    # Both faces found, their first fit refused: the edges' box sat over 5 px from the rough
    # region corners and the engine kept the corners, as it keeps a person's clicks against
    # edges that snapped to a printed border; a search's seeds are not clicks.
    23: "rough-seeds", 33: "rough-seeds", 150: "rough-seeds",
    # Front and side merged into one region (a fold too faint to close it) whose outline is a
    # pentagon: the bend at the fold's lower end too shallow to see. Split at the fold.
    19: "merged-pentagon",
    # The largest of the boxes over one place was the wrong one (a neighbour proposed on the
    # wrong side of the face); the right one, over the same place, was never measured.
    176: "second-over-one-place", 187: "second-over-one-place",
}
# The fold to a face of nearly the same shade is too faint for the second face's region to close
# (5, 13), or the side is a sliver 15 px wide (42): "only one face visible" before. The face beside
# the one found is proposed from the line segments leaving its corners and where the far side's
# colour change ends. A thin top face seen from little above it (71, 128, 135): its sides,
# converging toward a vanishing point close by, leave the front's corners 57-87 deg apart
# (proposals stopped at 50 deg).
NEIGHBOUR_PROPOSED = (5, 13, 42, 71, 128, 135)


@pytest.mark.parametrize(("seeds", "tol_px", "at_least"), [
    pytest.param(tuple(ONCE_REFUSED), 1.0, 7, id="once-refused-within-1px"),  # 9 of 9 measured
    pytest.param(NEIGHBOUR_PROPOSED, 3.0, 4, id="neighbour-proposed-within-3px"),  # 5 of 6 here
])
def test_scenes_once_refused_stay_found(seeds, tol_px, at_least):
    outcomes = _outcomes(seeds, tol_px)
    assert outcomes.wrong == [], outcomes
    assert len(outcomes.right) >= at_least, outcomes


def _neighbour_error(img: np.ndarray, face: np.ndarray, truth: np.ndarray) -> float:
    """How far (px) the best of the neighbours proposed beside `face` lies from `truth`."""
    lab = cv2.cvtColor(cv2.GaussianBlur(img, (0, 0), 1.0), cv2.COLOR_RGB2Lab)
    segments = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD).detect(lab[..., 0])[0].reshape(-1, 4)
    labf = lab.astype(np.float32)
    grad = (cv2.Sobel(labf, cv2.CV_32F, 1, 0) / 8, cv2.Sobel(labf, cv2.CV_32F, 0, 1) / 8)
    proposals = propose_neighbours(face, segments.astype(np.float64), grad, img.shape[:2])
    return min((float(np.linalg.norm(quad[:, None] - truth[None], axis=2).min(axis=1).max())
                for quad, _ in proposals), default=np.inf)


def test_propose_neighbours_finds_a_top_whose_sides_converge_steeply():
    # The top's sides leave the front's upper corners 76 deg apart, meeting ahead.
    img = np.full((400, 500, 3), 90, np.uint8)
    front = np.array([[150.0, 200.0], [350.0, 202.0], [348.0, 380.0], [152.0, 378.0]])
    top = np.array([[150.0, 200.0], [175.0, 168.0], [325.0, 170.0], [350.0, 202.0]])
    cv2.fillPoly(img, [np.round(front * 16).astype(np.int32)], (200, 180, 150), cv2.LINE_AA, 4)
    cv2.fillPoly(img, [np.round(top * 16).astype(np.int32)], (150, 140, 120), cv2.LINE_AA, 4)
    assert _neighbour_error(img, front, top) <= 3.0


def _two_faces() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grey picture of two faces side by side (a box's front and right side, the side's
    edges converging), the side barely darker than the front; and their corners."""
    img = np.full((400, 500, 3), 90, np.uint8)
    front = np.array([[150.0, 120.0], [290.0, 130.0], [288.0, 300.0], [152.0, 290.0]])
    side = np.array([[290.0, 130.0], [380.0, 150.0], [377.0, 282.0], [288.0, 300.0]])
    cv2.fillPoly(img, [np.round(front * 16).astype(np.int32)], (200, 180, 150), cv2.LINE_AA, 4)
    cv2.fillPoly(img, [np.round(side * 16).astype(np.int32)], (194, 174, 144), cv2.LINE_AA, 4)
    return img, front, side


def test_propose_neighbours_finds_the_side_beside_a_face():
    img, front, side = _two_faces()
    lab = cv2.cvtColor(cv2.GaussianBlur(img, (0, 0), 1.0), cv2.COLOR_RGB2Lab)
    segments = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD).detect(lab[..., 0])[0].reshape(-1, 4)
    labf = lab.astype(np.float32)
    grad = (cv2.Sobel(labf, cv2.CV_32F, 1, 0) / 8, cv2.Sobel(labf, cv2.CV_32F, 0, 1) / 8)
    proposals = propose_neighbours(front, segments.astype(np.float64), grad, img.shape[:2])
    assert proposals
    best = min(np.linalg.norm(quad[:, None] - side[None], axis=2).min(axis=1).max()
               for quad, _ in proposals)
    assert best <= 3.0  # a seed: the engine's edge fit places the corners

"""Zero-click along a video (prismcore.video.point_search.FrameSearch): each frame's search starts at
the box the frame before showed, so the box a person pointed at in the first frame is followed
while it moves, past a frame where it is missing; that frame is refused with the reason.

The frames are one photo of two equal boxes (`two_box_scene`, whose corners are known) shifted
sideways a little more each frame: far enough that the spec's own hint, near the box's left
edge, is off the box by the second frame.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from prismcore import InputError, ScanSpec
from prismcore.locate.search import find_points
from prismcore.video.point_search import FrameSearch, points_centre
from prismsynth.scenes import clutter_scene, empty_scene, two_box_scene

SHIFTS = (0, 40, None, 60)  # px to the right per frame; None: a frame without the boxes


@pytest.fixture(scope="module")
def scene() -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """The photo, the left box's corners (8, 2) px and a hint inside its outline near its left edge."""
    image, (left, _) = two_box_scene(0)
    centre = left.mean(axis=0)
    leftmost = left[np.argmin(left[:, 0])]
    hint = centre + 0.85 * (leftmost - centre)
    hull = cv2.convexHull(left.astype(np.float32))
    assert cv2.pointPolygonTest(hull, (float(hint[0]), float(hint[1])), False) > 0
    return image, left, (float(hint[0]), float(hint[1]))


def _shifted(image: np.ndarray, dx: int) -> np.ndarray:
    return np.roll(image, dx, axis=1)  # the wrapped columns are background


def test_the_box_pointed_at_is_followed_from_frame_to_frame(scene):
    image, left, hint = scene
    # The premise: in the second frame the spec's hint is off the box, so a search from it alone fails.
    assert not find_points(_shifted(image, SHIFTS[1]), hint=hint).ok
    spec = ScanSpec.model_validate({"image": "clip.avi", "points": "auto", "auto_points": {"hint": hint},
                                    "frames": {}})
    search = FrameSearch(spec)
    blank = empty_scene(0, image_size=(image.shape[1], image.shape[0]))
    for index, dx in enumerate(SHIFTS):
        if dx is None:
            with pytest.raises(InputError, match=r"^points auto: no box found"):
                search.resolve(index, blank)
            continue
        photo, found = search.resolve(index, _shifted(image, dx))
        assert photo.points == found.points and photo.auto_points is None and photo.frames is None
        truth = left + np.array([dx, 0.0])
        for xy in found.points.as_dict().values():
            assert np.linalg.norm(truth - xy, axis=1).min() <= 3.0


def test_points_centre_is_the_mean_of_the_points_given():
    spec = ScanSpec.model_validate({"image": "x.png", "points": [[0, 0], [4, 0], [4, 2], [4, 0], [6, 1]]})
    assert points_centre(spec.points) == pytest.approx((3.6, 0.6))


@pytest.mark.parametrize(("extra", "words"), [
    ({"frame_points": {"0": [[0, 0], [4, 0], [4, 2], [4, 0], [6, 1]]}}, "drop frame_points"),
    ({"side_image": "side.png"}, "not with side_image"),
])
def test_auto_points_on_a_video_refuse_what_cannot_go_with_them(extra, words):
    with pytest.raises(ValueError, match=words):
        ScanSpec.model_validate({"image": "clip.avi", "points": "auto", "frames": {}, **extra})


def test_frame_search_needs_a_video_spec_with_points_auto():
    with pytest.raises(ValueError, match="video spec"):
        FrameSearch(ScanSpec.model_validate({"image": "x.png", "points": "auto"}))


def test_a_box_that_jumped_away_from_the_last_hint_is_found_again():
    # Between two selected frames (every: 30, say) the box moved 200 px: the search around the
    # last box finds nothing there, so the frame is searched again as the spec says (no hint).
    image = clutter_scene(0, image_size=(640, 512)).image
    search = FrameSearch(ScanSpec.model_validate({"image": "clip.avi", "points": "auto", "frames": {}}))
    _, first = search.resolve(0, image)
    assert not find_points(_shifted(image, 200), hint=points_centre(first.points)).ok  # the premise
    _, again = search.resolve(1, _shifted(image, 200))
    for name, xy in again.points.as_dict().items():
        before = first.points.as_dict()[name]
        assert (xy is None) == (before is None)
        if xy is not None:
            assert np.hypot(xy[0] - before[0] - 200, xy[1] - before[1]) <= 1.0, name

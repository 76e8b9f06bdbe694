"""Points marked on one frame carried to the others (prismcore.video.tracking and box_motion).

Bounds with margins over the renders' seeds; the figures themselves: benchmarks/video_tracking.py.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from prismcore.errors import InputError
from prismcore.video.box_motion import fit_box_model
from prismcore.video.frame_select import viewing_spread
from prismcore.video.track_refine import box_refiner
from prismcore.video.tracking import TrackerSettings, track_points
from prismsynth import Box
from prismsynth.video import moving_clip

FRAMES = 40
SIZE = (640, 360)
FRONT = [0, 1, 2, 5]


@functools.cache
def _clip(seed: int) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    images, points = moving_clip(Box(120.0, 80.0, 60.0), FRAMES, image_size=SIZE, focal_px=600.0,
                                 sway_deg=8.0, seed=seed)
    return tuple(images), tuple(points)


def _worst(points: np.ndarray, truth: np.ndarray, rows: list[int] | None = None) -> float:
    d = np.linalg.norm(points - truth, axis=1)
    return float((d if rows is None else d[rows]).max())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_renders_tracked_and_refined_within_a_pixel(seed: int) -> None:
    images, truth = _clip(seed)
    report = set(range(0, FRAMES, 5)) | {FRAMES - 1}
    out = track_points(list(enumerate(images)), truth[0], 0, report=report, refine=box_refiner())
    assert sorted(out) == sorted(report)
    for index, frame in out.items():
        assert frame.points is not None, frame.reason
        assert _worst(frame.points, truth[index]) < 1.5, index
        assert frame.quality is not None and 0.0 <= frame.quality.confidence <= 1.0


@pytest.mark.parametrize(("seed", "motion"), [(0, "box"), (1, "box"), (0, "faces"), (1, "faces")])
def test_followed_every_frame_without_refinement(seed: int, motion: str) -> None:
    """The rigid box holds all seven points; each face's homography the front's (its second
    face's far corners drift)."""
    images, truth = _clip(seed)
    out = track_points(list(enumerate(images)), truth[0], 0, settings=TrackerSettings(motion=motion))
    assert len(out) == FRAMES
    rows = None if motion == "box" else FRONT
    worst = max(_worst(f.points, truth[i], rows) for i, f in out.items() if f.points is not None)
    assert all(f.points is not None for f in out.values())
    assert worst < (3.5 if motion == "box" else 2.5)
    q = out[FRAMES - 1].quality
    assert q is not None and q.inliers_front >= 10 and q.fb_error_px < 0.5 and q.steps == FRAMES - 1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_box_model_of_exact_points_is_the_rendered_box(seed: int) -> None:
    """From the seven exact points alone: the render's focal length and the box's proportions."""
    images, truth = _clip(seed)
    model, pose = fit_box_model(truth[0], "right", images[0].shape)
    assert model.focal_px == pytest.approx(600.0, rel=1e-3)
    assert (model.height, model.depth) == pytest.approx((80.0 / 120.0, 60.0 / 120.0), rel=1e-3)
    assert np.abs(model.project(pose) - truth[0]).max() < 0.05


def test_frames_before_the_marked_one_are_tracked_backwards() -> None:
    images, truth = _clip(0)
    start = 20
    out = track_points(list(enumerate(images)), truth[start], start, report={0, 10, start, 30},
                       refine=box_refiner())
    assert sorted(out) == [0, 10, start, 30]
    for index, frame in out.items():
        assert frame.points is not None, frame.reason
        assert _worst(frame.points, truth[index]) < 1.5


def test_a_lost_frame_is_left_out_and_the_track_picked_up_after_it() -> None:
    images, truth = _clip(1)
    frames = [img.copy() for img in images]
    box = truth[12]
    x0, y0 = np.floor(box.min(axis=0)).astype(int) - 5
    x1, y1 = np.ceil(box.max(axis=0)).astype(int) + 5
    frames[12][max(y0, 0):y1, max(x0, 0):x1] = frames[12][max(y0, 0):y1, max(x0, 0):x1].mean(axis=(0, 1))
    out = track_points(list(enumerate(frames)), truth[0], 0, report={5, 12, 20, 30}, refine=box_refiner())
    assert out[12].points is None and out[12].reason is not None and "lost" in out[12].reason
    for index in (5, 20, 30):
        assert out[index].points is not None, out[index].reason
        assert _worst(out[index].points, truth[index]) < 1.5


def test_a_cut_to_another_scene_ends_the_track() -> None:
    images, truth = _clip(0)
    other, _ = _clip(2)
    rng = np.random.default_rng(0)
    cut = [rng.integers(0, 60, img.shape, dtype=np.uint8) for img in other[:10]]  # a dark scene
    frames = list(enumerate([*images[:15], *cut]))
    out = track_points(frames, truth[0], 0, report={10, 15, 20})
    assert out[10].points is not None
    for index in (15, 20):
        assert out[index].points is None and "cut" in str(out[index].reason)


def test_a_box_that_no_longer_fits_is_named() -> None:
    images, truth = _clip(0)

    def refuse_at_20(image: np.ndarray, points: np.ndarray) -> np.ndarray:
        if image is images[20]:
            raise InputError("the fitted box sits 40 px from P5")
        return points

    out = track_points(list(enumerate(images)), truth[0], 0, report={10, 20, 30}, refine=refuse_at_20)
    assert out[20].points is None and "no longer fits" in str(out[20].reason) and "P5" in str(out[20].reason)
    assert out[10].points is not None and out[30].points is not None


def test_a_refused_box_anchors_nothing() -> None:
    """The track goes on from the last good frame: the refused frame is no step of it."""
    images, truth = _clip(0)

    def refuse_at_20(image: np.ndarray, points: np.ndarray) -> np.ndarray:
        if image is images[20]:
            raise InputError("the fitted box sits 40 px from P5")
        return points

    out = track_points(list(enumerate(images)), truth[0], 0, report={19, 20, 21}, refine=refuse_at_20)
    assert out[20].points is None
    q19, q21 = out[19].quality, out[21].quality
    assert q19 is not None and q21 is not None and (q19.steps, q21.steps) == (19, 20)
    assert out[21].points is not None and _worst(out[21].points, truth[21], FRONT) < 2.5


@pytest.mark.parametrize("shift_px", [0.0, 8.0])
def test_the_marked_frames_confidence_tells_how_far_the_refinement_moved_it(shift_px: float) -> None:
    images, truth = _clip(0)

    def move(image: np.ndarray, points: np.ndarray) -> np.ndarray:
        return points + np.array([shift_px, 0.0])

    out = track_points(list(enumerate(images[:3])), truth[0], 0, report={0}, refine=move)
    q = out[0].quality
    assert q is not None and q.refine_shift_px == pytest.approx(shift_px)
    # The confidence's refinement factor: exp(-(shift - 1 px) / 4 px) past a pixel.
    assert q.confidence <= np.exp(-max(shift_px - 1.0, 0.0) / 4.0) + 1e-12
    assert (q.confidence < 0.2) == (shift_px > 5)


@pytest.mark.parametrize("motion", ["box", "faces"])
def test_a_refinement_no_box_reproduces_is_not_taken_by_the_box(motion: str) -> None:
    """A refinement that snapped one corner 6 px away: the rigid box keeps its own points (and
    says how far the refinement would have moved them); each face's homography takes it."""
    images, truth = _clip(0)

    def snap_p5(image: np.ndarray, points: np.ndarray) -> np.ndarray:
        out = points.copy()
        if image is images[10]:
            out[4] += (0.0, 6.0)
        return out

    frames, settings = list(enumerate(images[:11])), TrackerSettings(motion=motion)
    frame = track_points(frames, truth[0], 0, report={10}, refine=snap_p5, settings=settings)[10]
    tracked = track_points(frames, truth[0], 0, report={10}, settings=settings)[10].points
    assert frame.points is not None and frame.quality is not None and tracked is not None
    assert frame.quality.refine_shift_px == pytest.approx(6.0)
    assert frame.quality.confidence < 0.5
    taken = snap_p5(images[10], tracked)
    np.testing.assert_allclose(frame.points, tracked if motion == "box" else taken, atol=1e-9)


def test_a_grey_frame_is_refined_too() -> None:
    images, truth = _clip(0)
    seen: list[tuple[int, ...]] = []

    def record(image: np.ndarray, points: np.ndarray) -> np.ndarray:
        seen.append(image.shape)
        return points

    grey = [img if i != 10 else img.mean(axis=2).astype(np.uint8) for i, img in enumerate(images[:12])]
    out = track_points(list(enumerate(grey)), truth[0], 0, report={0, 10}, refine=record)
    assert seen == [images[0].shape, images[10].shape]
    q = out[10].quality
    assert q is not None and q.refine_shift_px == 0.0


def test_bad_input_is_refused() -> None:
    images, truth = _clip(0)
    with pytest.raises(InputError, match="not among"):
        track_points(list(enumerate(images[:5])), truth[0], 9)
    with pytest.raises(InputError, match="seven"):
        track_points(list(enumerate(images[:5])), truth[0][:5], 0)
    with pytest.raises(InputError, match="motion"):
        track_points(list(enumerate(images[:5])), truth[0], 0, settings=TrackerSettings(motion="spline"))


def test_viewing_spread_keeps_the_extremes_of_a_sweep() -> None:
    _, truth = _clip(0)
    points = dict(enumerate(truth))
    chosen = viewing_spread(points, 5)
    assert len(chosen) == 5 and chosen == sorted(chosen)
    assert viewing_spread(points, 100) == list(range(FRAMES))

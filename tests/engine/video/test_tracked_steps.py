"""The steps the CLI and the worker share for points marked on one frame (`prismcore.video.tracked`):
the refinement plans with the marked frame's own photo spec, the per-frame spec gives each
tracked frame its points, tracked_points.json reads back as it was written, and a marked frame
past the video's end, or a tracking over the span cap, is refused."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore.errors import InputError
from prismcore.io.video_decode import VideoInfo
from prismcore.spec import ScanSpec
from prismcore.video.frames import frame_spec
from prismcore.video.tracked import (
    Tracking,
    check_points_frame,
    check_points_frame_span,
    per_frame_spec,
    refine_fields,
    span_problem,
    track_video,
    tracked_frame_spec,
    tracked_json,
)
from prismcore.video.tracking import TrackedFrame, TrackQuality

POINTS = [[198, 68], [476, 95], [458, 306], [476, 95], [518, 71], [209, 239], [499, 247]]
EDGE = {"kind": "edge", "edge": "width", "length_mm": 120.0}


def _spec(**extra) -> ScanSpec:
    return ScanSpec.model_validate({"image": "clip.avi", "points": POINTS, "points_frame": 3,
                                    "frames": {"every": 2}, **extra})


@pytest.mark.parametrize("extra", [{}, {"scale": EDGE, "focal_px": 600.0, "side_face": "right"},
                                   {"max_pixels": 1_000_000, "tolerance": 12, "method": "default"}],
                         ids=["bare", "scale-focal-face", "caps"])
def test_the_refinement_plans_with_the_frames_own_spec(extra: dict) -> None:
    spec = _spec(**extra)
    fields = refine_fields(spec)
    photo = frame_spec(spec, 3)
    # box_refiner adds the image and the points: the plan sees the measurement's spec, no less.
    rebuilt = ScanSpec.model_validate({"image": photo.image, "points": photo.points.model_dump(), **fields,
                                       "formats": photo.formats})
    assert rebuilt == photo


def _tracked() -> dict[int, TrackedFrame]:
    base = np.array(POINTS, dtype=np.float64)
    quality = TrackQuality(40, 30, 10, 0.2, 0.9, 0.3, 2)
    return {0: TrackedFrame(0, base + 1.25, quality), 2: TrackedFrame(2, None, None, "lost: 3 inliers"),
            3: TrackedFrame(3, base, quality), 4: TrackedFrame(4, base - 0.5, quality)}


def test_tracked_points_read_back_and_give_each_frame_its_own_points() -> None:
    doc = tracked_json(_tracked())
    assert list(doc) == ["0", "2", "3", "4"] and doc["2"] == {"reason": "lost: 3 inliers"}
    tracking = Tracking.from_json(3, doc)
    direct = Tracking.of(3, _tracked())  # as the tracker returned it, before the JSON's rounding
    assert tracking.left == direct.left and list(tracking.good) == list(direct.good) == [0, 3, 4]
    for index, points in direct.good.items():
        np.testing.assert_allclose(tracking.good[index], points, atol=5e-4)
    assert tracking.block() == {"points_frame": 3, "tracked": [0, 3, 4], "left_out": {"2": "lost: 3 inliers"}}
    assert tracking.warnings() == ["frame 2 left out by the tracking: lost: 3 inliers"]
    per_frame = per_frame_spec(_spec(), tracking)
    assert per_frame.points_frame is None and per_frame.frames is not None
    assert per_frame.frames.indices == [0, 3, 4]
    for index in (0, 3, 4):
        got = np.array([per_frame.frame_points[index].as_dict()[f"p{k}"] for k in range(1, 8)])
        np.testing.assert_allclose(got, tracking.good[index], atol=1e-3)
        assert frame_spec(per_frame, index).points == per_frame.frame_points[index]
    with pytest.raises(InputError, match="frame 2 has no reference points"):
        frame_spec(per_frame, 2)


def test_nothing_tracked_and_a_marked_frame_past_the_end_are_refused() -> None:
    with pytest.raises(InputError, match="no frame of 'clip' could be tracked from frame 3: cut"):
        Tracking(3, {}, {5: "cut to another scene"}).require_some("'clip'")
    info = VideoInfo(width=640, height=360, frame_count=3, fps=25.0, codec="MJPG", duration_s=0.12)
    with pytest.raises(InputError, match=r"points_frame 3 is past the video's end: it has 3 frames \(0-2\)"):
        check_points_frame(_spec(), info)
    check_points_frame(_spec(), VideoInfo(width=640, height=360, frame_count=4, fps=25.0, codec="MJPG",
                                          duration_s=0.16))


@pytest.mark.parametrize("extra", [{}, {"scale": EDGE, "focal_px": 600.0, "side_face": "right"},
                                   {"max_pixels": 1_000_000, "tolerance": 12, "method": "default"}],
                         ids=["bare", "scale-focal-face", "caps"])
def test_one_frames_spec_is_the_one_the_whole_per_frame_spec_gives(extra: dict) -> None:
    # The oracle: the photo spec of the per-frame spec built from every tracked frame.
    base = np.array(POINTS, dtype=np.float64)
    quality = TrackQuality(40, 30, 10, 0.2, 0.9, 0.3, 2)
    tracked = {i: TrackedFrame(i, base + 0.37 * i, quality) for i in range(0, 200, 3)}
    tracked[7] = TrackedFrame(7, None, None, "lost: 3 inliers")
    tracking = Tracking.of(3, tracked)
    spec = _spec(**extra)
    whole = per_frame_spec(spec, tracking)
    for index in (0, 3, 99, 198):
        assert tracked_frame_spec(spec, tracking, index) == frame_spec(whole, index)
    with pytest.raises(InputError, match="frame 7 left out by the tracking: lost: 3 inliers"):
        tracked_frame_spec(spec, tracking, 7)
    with pytest.raises(InputError, match="frame 8 left out by the tracking: not among the frames tracked"):
        tracked_frame_spec(spec, tracking, 8)


@pytest.mark.parametrize(("frames", "marked", "cap", "read"), [
    ([10, 20], 15, 11, None), ([10, 20], 15, 10, (10, 20)),  # 10..20 is 11 frames
    ([100], 5, 96, None), ([100], 5, 95, (5, 100)),  # the marked frame before the selection
    ([0, 1, 2], 299, 300, None), ([0, 1, 2], 300, 300, (0, 300)),  # after it
])
def test_the_span_a_tracking_reads_is_capped(frames: list[int], marked: int, cap: int,
                                             read: tuple[int, int] | None) -> None:
    problem = span_problem(frames, marked, cap)
    if read is None:
        assert problem is None
        check_points_frame_span(frames, marked, cap)
        return
    lo, hi = read
    assert problem == (f"points_frame {marked}: tracking the points to the selected frames reads frames "
                       f"{lo}-{hi}, {hi - lo + 1} frames, over the cap of {cap} frames one tracking may "
                       "read: mark the points on a frame nearer the selected ones, or select frames "
                       f"nearer frame {marked} (start_s/end_s or indices)")
    with pytest.raises(InputError, match="over the cap"):
        check_points_frame_span(frames, marked, cap)
    # The engine refuses before it opens the video: the path need not exist.
    spec = ScanSpec.model_validate({"image": "clip.avi", "points": POINTS, "points_frame": marked,
                                    "frames": {"indices": frames}})
    with pytest.raises(InputError, match="over the cap"):
        track_video(spec, "/nonexistent/clip.avi", frames, max_span=cap)

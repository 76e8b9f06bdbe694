"""Frame selection: every Nth, a time range, explicit indices, the K sharpest, and the cap."""

from __future__ import annotations

import itertools
from fractions import Fraction

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from prismcore import InputError
from prismcore.spec import FrameSelection
from prismcore.video.frames import VideoInfo, frame_sharpness, probe_video, select_frames
from prismsynth import write_video

INFO = VideoInfo(frame_count=100, fps=25.0, width=640, height=512, codec="MJPG", duration_s=4.0)


def _oracle(n: int, fps: float, every: int | None, start: float | None, end: float | None) -> list[int]:
    """Frames whose time i / fps lies in [start, end), then every Nth: exact arithmetic on the
    decimals as written."""
    rate = Fraction(str(fps))
    lo = Fraction(str(start)) if start is not None else Fraction(0)
    hi = Fraction(str(end)) if end is not None else Fraction(n) / rate + 1
    return [i for i in range(n) if lo <= Fraction(i) / rate < hi][:: every or 1]


@pytest.mark.parametrize(
    ("selection", "expected"),
    [
        ({}, list(range(100))),
        ({"every": 10}, list(range(0, 100, 10))),
        ({"start_s": 0.4, "end_s": 0.6}, [10, 11, 12, 13, 14]),
        ({"start_s": 3.9}, [98, 99]),
        ({"end_s": 0.12}, [0, 1, 2]),
        ({"start_s": 1.0, "end_s": 2.0, "every": 7}, [25, 32, 39, 46]),
        ({"indices": [9, 3, 99]}, [3, 9, 99]),
    ],
    ids=str,
)
def test_selections_pick_the_frames_they_say(selection, expected):
    assert select_frames("v.avi", FrameSelection(**selection), INFO, max_frames=500) == expected


@given(
    n=st.integers(1, 400),
    fps=st.sampled_from([25.0, 30.0, 29.97, 12.5, 60.0]),
    every=st.none() | st.integers(1, 30),
    start=st.none() | st.integers(0, 1500).map(lambda c: c / 100),
    length=st.none() | st.integers(1, 1500).map(lambda c: c / 100),
)
def test_time_range_and_every_match_exact_arithmetic(n, fps, every, start, length):
    end = None if length is None else round((start or 0.0) + length, 2)
    info = VideoInfo(n, fps, 64, 48, "MJPG", n / fps)
    expected = _oracle(n, fps, every, start, end)
    selection = FrameSelection(every=every, start_s=start, end_s=end)
    if expected:
        assert select_frames("v.avi", selection, info, max_frames=10_000) == expected
    else:
        with pytest.raises(InputError, match=r"picks no frame|past the end"):
            select_frames("v.avi", selection, info, max_frames=10_000)


@pytest.mark.parametrize(
    ("selection", "max_frames", "needle"),
    [
        ({"indices": [3, 100, 250]}, 500,
         "frame indices 100, 250 out of range: 'v.avi' has 100 frames (0-99)"),
        ({}, 50, "picks 100 frames of 'v.avi', over the cap of 50 frames per video: narrow it with every"),
        ({"indices": list(range(20))}, 10, "picks 20 frames of 'v.avi', over the cap of 10"),
        ({"every": 2}, 49, "picks 50 frames"),
        ({"start_s": 4.0}, 500, "start_s 4.0 is past the end of 'v.avi' (4.000 s, 100 frames)"),
        ({"start_s": 0.1, "end_s": 0.11}, 500, "picks no frame of 'v.avi'"),
        ({"every": 10, "sharpest": 11}, 500, "sharpest 11 is more than the 10 candidate frames"),
        ({"sharpest": 20}, 10, "sharpest 20 is over the cap of 10"),
    ],
    ids=["indices-out-of-range", "over-cap", "indices-over-cap", "every-over-cap", "start-past-end",
         "empty-range", "sharpest-too-many", "sharpest-over-cap"],
)
def test_bad_selections_are_input_errors_quoting_the_value(selection, max_frames, needle):
    with pytest.raises(InputError) as caught:
        select_frames("v.avi", FrameSelection(**selection), INFO, max_frames=max_frames)
    assert needle in str(caught.value)


def test_time_range_needs_a_frame_rate():
    info = VideoInfo(10, 0.0, 64, 48, "MJPG", 0.0)
    with pytest.raises(InputError, match="states no frame rate"):
        select_frames("v.avi", FrameSelection(start_s=1.0), info, max_frames=10)
    assert select_frames("v.avi", FrameSelection(every=4), info, max_frames=10) == [0, 4, 8]


def test_sharpness_falls_as_blur_grows(clip_scenes):
    image = clip_scenes[0].image
    scores = [frame_sharpness(image)] + [frame_sharpness(cv2.GaussianBlur(image, (0, 0), s))
                                         for s in (0.7, 1.5, 3.0)]
    assert all(a > b for a, b in itertools.pairwise(scores)), scores
    big = cv2.resize(image, (1280, 1024), interpolation=cv2.INTER_CUBIC)  # rated at 640 px wide
    full = cv2.Laplacian(cv2.cvtColor(big, cv2.COLOR_RGB2GRAY), cv2.CV_64F).var()
    assert frame_sharpness(big) == pytest.approx(
        frame_sharpness(cv2.resize(big, (640, 512), interpolation=cv2.INTER_AREA)), rel=0.01)
    assert full < 0.5 * frame_sharpness(big)


@pytest.fixture(scope="module")
def blurred_clip(clip_scenes, tmp_path_factory):
    """The clip with frames 1 and 4 out of focus (a Gaussian blur of 1.5 px)."""
    path = tmp_path_factory.mktemp("blur") / "blur.avi"
    frames = [cv2.GaussianBlur(s.image, (0, 0), 1.5) if i in (1, 4) else s.image
              for i, s in enumerate(clip_scenes)]
    write_video(frames, path, codec="MJPG")
    return path


@pytest.mark.parametrize(
    ("selection", "expected"),
    [
        ({"sharpest": 4}, [0, 2, 3, 5]),
        ({"sharpest": 2, "every": 2}, [0, 2]),  # candidates 0, 2, 4
        ({"sharpest": 2, "start_s": 0.04, "end_s": 0.2}, [2, 3]),  # candidates 1-4
        ({"sharpest": 1, "start_s": 0.16}, [5]),  # candidates 4, 5
    ],
    ids=str,
)
def test_sharpest_avoids_the_blurred_frames(blurred_clip, selection, expected):
    info = probe_video(blurred_clip)
    assert select_frames(blurred_clip, FrameSelection(**selection), info, max_frames=10) == expected


def test_sharpest_of_identical_frames_keeps_the_earliest(tmp_path):
    path = tmp_path / "same.avi"
    write_video([np.full((48, 64, 3), 90, np.uint8)] * 5, path, codec="MJPG")
    assert select_frames(path, FrameSelection(sharpest=2), probe_video(path), max_frames=5) == [0, 1]

"""Decoding videos: probe, stream frames (in order, by seeking or not), and refuse bad files."""

from __future__ import annotations

import tracemalloc

import cv2
import numpy as np
import pytest
from video_clips import CLIP_FPS, CLIP_FRAMES, CODEC_IDS, CODECS, read_stamp

from prismcore import InputError
from prismcore.video.frames import iter_frames, probe_video
from prismsynth import write_video

# What OpenCV reports as the FourCC of each codec (MPEG-4 part 2 reads as "FMP4" whatever the tag).
FOURCC = {"MJPG": {"MJPG"}, "XVID": {"FMP4", "XVID"}, "mp4v": {"FMP4", "mp4v"},
          "h264": {"h264", "avc1", "H264"}}


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b) ** 2))
    return 10 * np.log10(255.0**2 / mse)


@pytest.mark.parametrize(("ext", "codec"), CODECS, ids=CODEC_IDS)
def test_probe_reads_count_rate_size_and_codec(make_clip, ext, codec):
    info = probe_video(make_clip(ext, codec))
    assert (info.frame_count, info.fps, info.width, info.height) == (CLIP_FRAMES, CLIP_FPS, 640, 512)
    assert info.codec in FOURCC[codec]
    assert info.duration_s == pytest.approx(CLIP_FRAMES / CLIP_FPS)


@pytest.mark.parametrize(("ext", "codec"), CODECS, ids=CODEC_IDS)
def test_frames_decode_to_the_rendered_pictures(make_clip, clip_scenes, ext, codec):
    frames = list(iter_frames(make_clip(ext, codec), range(CLIP_FRAMES)))
    assert [i for i, _ in frames] == list(range(CLIP_FRAMES))
    for i, frame in frames:
        assert frame.dtype == np.uint8 and frame.shape == (512, 640, 3) and frame.flags.c_contiguous
        # RGB, not BGR: swapped channels would fall far below this on the coloured box
        assert _psnr(frame, clip_scenes[i].image) > 33.0, (i, _psnr(frame, clip_scenes[i].image))


@pytest.mark.parametrize(("ext", "codec"), [("avi", "MJPG"), ("mp4", "mp4v"), ("mp4", "h264")],
                         ids=["avi-MJPG", "mp4-mp4v", "mp4-h264"])
def test_seeking_gives_the_frames_decoding_through_gives(make_long_clip, ext, codec):
    path = make_long_clip(ext, codec, 120)
    through = dict(iter_frames(path, range(120)))
    assert [read_stamp(f) for f in through.values()] == list(range(120))
    wanted = [117, 3, 4, 40, 41, 90, 3]  # unsorted, repeated: yielded once each, in order
    sought = list(iter_frames(path, wanted, seek_gap=5))
    assert [i for i, _ in sought] == [3, 4, 40, 41, 90, 117]
    for i, frame in sought:
        assert read_stamp(frame) == i
        np.testing.assert_array_equal(frame, through[i])


def test_frames_are_streamed_not_held(make_long_clip):
    path = make_long_clip("avi", "MJPG", 240)  # 240 MB of pixels when held at once
    frame_bytes = 640 * 512 * 3
    tracemalloc.start()
    try:
        previous = None
        for i, frame in iter_frames(path, range(240)):
            if previous is not None:  # each frame is the caller's own, not a reused buffer
                assert not np.shares_memory(frame, previous)
            assert read_stamp(frame) == i
            previous = frame
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 4 * frame_bytes, peak / frame_bytes


def test_probe_counts_frames_that_decode_when_the_header_claims_more(make_long_clip, tmp_path):
    data = make_long_clip("avi", "MJPG", 120).read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    info = probe_video(cut)
    assert 50 <= info.frame_count <= 62, info
    last = list(iter_frames(cut, [info.frame_count - 1]))
    assert read_stamp(last[0][1]) == info.frame_count - 1
    with pytest.raises(InputError, match=f"frame {info.frame_count} is past the end"):
        list(iter_frames(cut, [info.frame_count]))


def _empty_avi(path):
    cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48)).release()


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda p, clip: p.write_text("just text, not a video"), "is not a video"),
        (lambda p, clip: p.write_bytes(cv2.imencode(".png", np.zeros((8, 8, 3), np.uint8))[1].tobytes()),
         "is not a video"),
        (lambda p, clip: p.write_bytes(clip.read_bytes()[:2000]), "truncated or corrupt MP4"),
        (lambda p, clip: p.write_bytes(clip.read_bytes()[:-4000]), "truncated or corrupt MP4"),
        (lambda p, clip: p.write_bytes(b"RIFF\x00\x10\x00\x00AVI LIST" + bytes(4000)),
         "truncated or corrupt AVI"),
        (lambda p, clip: _empty_avi(p), "no decodable frames"),
        (lambda p, clip: None, "No such file"),
        (lambda p, clip: p.mkdir(), "cannot read"),
    ],
    ids=["text", "png", "mp4-head-only", "mp4-tail-cut", "avi-garbage", "zero-frames", "missing",
         "directory"],
)
def test_bad_files_are_input_errors_naming_the_file(make_clip, tmp_path, make, needle):
    path = tmp_path / "video.avi"
    make(path, make_clip("mp4", "h264"))
    with pytest.raises(InputError, match=needle) as caught:
        probe_video(path)
    assert str(path) in str(caught.value)
    with pytest.raises(InputError):
        list(iter_frames(path, [0]))


def test_frame_size_over_the_pixel_limit_is_refused(make_clip):
    with pytest.raises(InputError, match="640x512 = 327680 pixel frames, over the limit of 300000"):
        probe_video(make_clip("avi", "MJPG"), max_pixels=300_000)


def test_negative_index_is_refused(make_clip):
    with pytest.raises(InputError, match="frame index -1 is negative"):
        list(iter_frames(make_clip("avi", "MJPG"), [-1, 2]))


def test_write_video_refuses_frames_of_another_size(tmp_path):
    frames = [np.zeros((48, 64, 3), np.uint8), np.zeros((40, 64, 3), np.uint8)]
    with pytest.raises(ValueError, match="in a 64x48 video"):
        write_video(frames, tmp_path / "x.avi", codec="MJPG")

"""Each frame of a video measured as a photo: dimensions against the known box, per codec."""

from __future__ import annotations

import numpy as np
import pytest
from video_clips import CLIP_BOX, CLIP_FRAMES, CODEC_IDS, CODECS

from prismcore import ScanSpec, run_scan
from prismcore.report import report_dict
from prismcore.video.frames import frame_spec, iter_frames, probe_video, select_frames
from prismcore.video.summary import DIMENSIONS, summarize

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
TRUTH = {"width": CLIP_BOX.width_mm, "height": CLIP_BOX.height_mm, "depth": CLIP_BOX.depth_mm}
# The engine is within 2 % on oblique photos; the clip's frames measured 0.35 % (worst dimension,
# worst frame) as rendered and 0.42-0.53 % after each codec (MJPEG, MPEG-4 part 2, H.264 as the
# fixtures encode them): the bound leaves room for other FFmpeg builds, not for a real fault.
BOUND = 0.012


def _clicks(scene) -> list[list[float]]:
    return [[float(v) for v in np.rint(scene.points[n])] for n in NAMES]


def _specs(path, scenes) -> dict[str, ScanSpec]:
    common = {"image": str(path), "focal_px": scenes[0].focal_px,
              "scale": {"kind": "pinhole", "distance_mm": scenes[0].distance_mm}}
    return {
        # a fixed camera's points: frame 0's clicks serve every frame (the camera sways < 1 deg)
        "fixed": ScanSpec.model_validate({**common, "points": _clicks(scenes[0]), "frames": {}}),
        "per_frame": ScanSpec.model_validate(
            {**common, "frame_points": {i: _clicks(s) for i, s in enumerate(scenes)}}),
    }


def _errors(report: dict) -> dict[str, float]:
    dims = report["dimensions"]
    assert dims["unit"] == "mm"
    return {k: abs(dims[k] - v) / v for k, v in TRUTH.items()}


@pytest.fixture(scope="module")
def raw_errors(clip_scenes) -> dict[tuple[str, int], dict[str, float]]:
    """The engine's own error on each rendered frame, per spec: the same for every codec, so
    measured once (the path in the spec is not read when the frame is given)."""
    return {(name, i): _errors(report_dict(run_scan(frame_spec(spec, i), scene.image).report))
            for name, spec in _specs("clip", clip_scenes).items()
            for i, scene in enumerate(clip_scenes)}


# The fast tier measures each codec once; its other containers (which test_video_decode reads in
# every tier) are measured in the whole suite.
FAST = {("avi", "MJPG"), ("avi", "XVID"), ("mp4", "mp4v"), ("mp4", "h264")}


@pytest.mark.parametrize(("ext", "codec"), [
    pytest.param(ext, codec, id=name, marks=() if (ext, codec) in FAST else pytest.mark.slow)
    for (ext, codec), name in zip(CODECS, CODEC_IDS, strict=True)])
def test_every_frame_measures_the_box(make_clip, clip_scenes, raw_errors, ext, codec):
    path = make_clip(ext, codec)
    info = probe_video(path)
    for name, spec in _specs(path, clip_scenes).items():
        indices = select_frames(path, spec.frames, info, max_frames=CLIP_FRAMES)
        assert indices == list(range(CLIP_FRAMES))
        reports = {}
        for i, frame in iter_frames(path, indices):
            decoded = report_dict(run_scan(frame_spec(spec, i), frame).report)
            errors = _errors(decoded)
            assert max(errors.values()) < BOUND, (name, i, errors)
            # what the codec costs on top of the engine's own error
            lost = {k: abs(errors[k] - raw_errors[name, i][k]) for k in TRUTH}
            # An edge the codec blurs below the clear-edge test falls back to its click, and the
            # lens-distortion estimate (no camera given) then reads the remaining edges alone:
            # that costs up to ~1 % on frame 3 (it was under 0.6 % before that estimate).
            assert max(lost.values()) < BOUND, (name, i, lost, decoded["warnings"])
            reports[i] = decoded
        summary = summarize(reports, fps=info.fps)
        for k in DIMENSIONS:
            values = np.array([reports[i]["dimensions"][k] for i in indices])
            s = summary["dimensions"][k]
            assert s["median"] == pytest.approx(np.median(values), abs=1e-6)
            assert s["spread"] == pytest.approx(np.ptp(values), abs=1e-6)
            assert s["std"] == pytest.approx(np.std(values, ddof=1), abs=1e-6)
            assert abs(s["median"] - TRUTH[k]) / TRUTH[k] < BOUND
            assert s["relative_spread"] < 2 * BOUND


def test_frames_listed_in_frame_points_are_the_ones_measured(make_clip, clip_scenes):
    path = make_clip("mp4", "h264")
    spec = ScanSpec.model_validate({
        "image": str(path), "focal_px": clip_scenes[0].focal_px,
        "scale": {"kind": "pinhole", "distance_mm": clip_scenes[0].distance_mm},
        "frame_points": {4: _clicks(clip_scenes[4]), 1: _clicks(clip_scenes[1])}})
    frames = dict(iter_frames(path, select_frames(path, spec.frames, probe_video(path), max_frames=2)))
    assert sorted(frames) == [1, 4]
    for i, frame in frames.items():
        assert max(_errors(report_dict(run_scan(frame_spec(spec, i), frame).report)).values()) < BOUND

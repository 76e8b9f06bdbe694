"""The video parts of the spec: FrameSelection, per-frame points, frame_spec; telling videos by bytes."""

from __future__ import annotations

import io
import json
import subprocess
import sys

import jsonschema
import numpy as np
import pytest
from PIL import Image
from pydantic import ValidationError
from video_clips import CODEC_IDS, CODECS

from prismcore import InputError, ScanSpec, run_scan
from prismcore.io.containers import video_container
from prismcore.io.images import load_image
from prismcore.spec import FrameSelection
from prismcore.video.frames import frame_spec, is_video

P = [[10, 10], [50, 12], [50, 40], [50, 12], [60, 11]]
Q = [[11, 10], [51, 12], [51, 40], [51, 12], [61, 11]]


def test_frame_points_decide_the_frames_and_survive_a_round_trip():
    spec = ScanSpec.model_validate({"image": "v.mp4", "frame_points": {"7": P, "2": Q}})
    assert spec.is_video and spec.frames.indices == [2, 7] and spec.points is None
    again = ScanSpec.model_validate(json.loads(spec.model_dump_json()))
    assert again == spec
    assert frame_spec(spec, 7).points.p2 == (50.0, 12.0)
    assert frame_spec(spec, 2).points.p2 == (51.0, 12.0)
    with pytest.raises(InputError, match=r"frame 3 has no reference points .* \(it gives frames \[2, 7\]\)"):
        frame_spec(spec, 3)


def test_frame_spec_is_the_photo_spec_of_one_frame():
    spec = ScanSpec.model_validate({"image": "v.mp4", "points": P, "frames": {"every": 5},
                                    "scale": {"kind": "mm_per_px", "front": 0.5}, "formats": ["ply"]})
    one = frame_spec(spec, 10)
    assert not one.is_video and one.frame_points is None
    assert one.model_dump(exclude={"frames"}) == spec.model_dump(exclude={"frames"})
    with pytest.raises(ValueError, match="needs a video spec"):
        frame_spec(one, 0)
    with pytest.raises(InputError, match="is a video spec"):  # plan_scan will not take it whole
        run_scan(spec, np.zeros((64, 64, 3), np.uint8))


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        ({"frames": {"every": 0}}, "frames.every: Input should be greater than or equal to 1"),
        ({"frames": {"sharpest": 0}}, "frames.sharpest: Input should be greater than or equal to 1"),
        ({"frames": {"start_s": -1}}, "frames.start_s: Input should be greater than or equal to 0"),
        ({"frames": {"end_s": float("inf")}}, "frames.end_s: Input should be a finite number"),
        ({"frames": {"start_s": 3.0, "end_s": 2.5}}, "end_s 2.5 must be after start_s 3.0"),
        ({"frames": {"indices": []}}, "frames.indices: List should have at least 1 item"),
        ({"frames": {"indices": [-2]}}, "frames.indices.0: Input should be greater than or equal to 0"),
        ({"frames": {"indices": [4, 1, 4, 1, 9]}}, "frame indices repeated: [1, 4]"),
        ({"frames": {"indices": [1], "every": 3}}, "indices name the frames themselves: drop every=3"),
        ({"frames": {"nth": 3}}, "frames.nth: Extra inputs are not permitted"),
        ({"frames": {}, "side_image": "s.png"}, "side_image 's.png' cannot be used with frames"),
        ({"points": None, "frame_points": {"1": P}, "frames": {"every": 2}},
         'frame_points measures exactly frames [1]: drop frames or give frames.indices equal to them, '
         'got frames={"every":2}'),
        ({"frame_points": {"1": P}}, "give points (the same for every frame) or frame_points"),
        ({"points": None, "frame_points": {"x": P}}, "frame_points.x.[key]: Value error, key 'x' is not a "
         "frame index: give the index in digits only (0 the first frame)"),
        ({"points": None, "frame_points": {"-1": P}}, "frame_points.-1.[key]: Value error, key '-1' is not"),
        # JSON's keys are strings: digits only, as the published schema says (not " 3", "+3", "1_0")
        *(({"points": None, "frame_points": {k: P}}, f"frame_points.{k}.[key]: Value error, key {k!r}")
          for k in (" 3", "+3", "1_0", "3.0")),
        ({"points": None}, "points: the reference points are missing"),
    ],
    ids=lambda v: v if isinstance(v, str) and len(v) < 40 else None,
)
def test_bad_video_specs_name_the_field_and_value(spec, needle):
    data = {"image": "v.avi", "points": P, **spec}
    with pytest.raises(ValidationError) as caught:
        ScanSpec.model_validate(data)
    first = caught.value.errors()[0]
    text = ".".join(str(p) for p in first["loc"]) + ": " + first["msg"] if first["loc"] else first["msg"]
    assert needle in text, text


def test_the_schema_describes_frames_and_spec_import_stays_light():
    schema = ScanSpec.model_json_schema()
    assert {"frames", "frame_points"} <= set(schema["properties"])
    assert set(FrameSelection.model_json_schema()["properties"]) == {"every", "start_s", "end_s",
                                                                      "indices", "sharpest"}
    validator = jsonschema.Draft202012Validator(schema)
    named = dict(zip(("p1", "p2", "p3", "p4", "p5"), P, strict=True))  # the schema's form of points
    assert validator.is_valid({"image": "v.avi", "frame_points": {"3": named}})
    assert validator.is_valid({"image": "v.avi", "points": named, "frames": {"every": 2, "sharpest": 3}})
    assert not validator.is_valid({"image": "v.avi", "frames": {}})  # no points of either kind
    assert not validator.is_valid({"image": "v.avi", "points": named, "frames": {"every": 0}})
    code = "import sys, prismcore.spec; print(sorted({'numpy', 'cv2'} & set(sys.modules)))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]"


def _image_bytes(fmt: str) -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", (8, 8)).save(buf, format=fmt)
    return buf.getvalue()


@pytest.mark.parametrize(("ext", "codec"), CODECS, ids=CODEC_IDS)
def test_encoded_videos_are_told_by_their_bytes(make_clip, ext, codec):
    path = make_clip(ext, codec)
    assert is_video(path) and is_video(path.read_bytes()[:16])
    assert video_container(path.read_bytes()) == ext


@pytest.mark.parametrize(
    ("head", "expected"),
    [
        (b"\x00\x00\x00\x14ftypqt  \x00\x00\x00\x00", "mov"),
        (b"\x00\x00\x00\x1cftypisom\x00\x00\x02\x00", "mp4"),
        (b"\x00\x00\x00\x1cftyp3gp5\x00\x00\x02\x00", "mp4"),
        (b"\x00\x00\x00\x08wide\x00\x00\x00\x00mdat", "mov"),
        (b"\x00\x00\x06\x8cmoov\x00\x00\x00\x6cmvhd", "mov"),
        (b"\x1a\x45\xdf\xa3\x9f\x42\x86\x81\x01", "mkv"),
        (b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00", None),
        (b"\x00\x00\x00\x1cftypavif\x00\x00\x00\x00", None),
        (b"\x00\x00\x00\x1cftypM4A \x00\x00\x00\x00", None),
        (b"RIFF\x00\x01\x00\x00WAVEfmt ", None),
        (b"this is free text", None),
        (b"", None),
    ],
    ids=repr,
)
def test_container_sniffing(head, expected):
    assert video_container(head) == expected


@pytest.mark.parametrize("fmt", ["PNG", "JPEG", "BMP", "TIFF", "WEBP"])
def test_photos_are_not_videos(fmt, tmp_path):
    data = _image_bytes(fmt)
    (tmp_path / "photo.avi").write_bytes(data)  # the name lies; the bytes do not
    assert not is_video(data) and not is_video(tmp_path / "photo.avi")
    assert not is_video(tmp_path / "missing.avi")


def test_loading_a_video_as_a_photo_says_it_is_a_video(make_clip):
    with pytest.raises(InputError, match=r"is a video \(AVI\), not a photo"):
        load_image(make_clip("avi", "MJPG"))

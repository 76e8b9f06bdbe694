"""`points_frame` (issue 29): seven points marked on one frame of a video, tracked to the others."""

from __future__ import annotations

import subprocess
import sys

import pytest
from pydantic import ValidationError

from prismcore.spec import ScanSpec
from prismcore.video.frames import frame_spec

POINTS = [[10, 10], [100, 12], [98, 60], [100, 12], [130, 5], [12, 58], [128, 50]]
VIDEO = {"image": "clip.mp4", "points": POINTS, "frames": {"every": 5}}
EDGE = {"kind": "edge", "edge": "width", "length_mm": 120.0}


def test_points_frame_is_kept_and_left_out_of_each_frame_spec() -> None:
    spec = ScanSpec.model_validate({**VIDEO, "points_frame": 7})
    assert spec.points_frame == 7
    one = frame_spec(spec, 10)
    assert one.points_frame is None and one.frames is None and one.points == spec.points


def test_joint_fit_over_tracked_frames_needs_a_known_edge() -> None:
    spec = ScanSpec.model_validate({**VIDEO, "points_frame": 0, "fit": "joint", "scale": EDGE})
    assert spec.fit == "joint"
    with pytest.raises(ValidationError, match="known edge"):
        ScanSpec.model_validate({**VIDEO, "points_frame": 0, "fit": "joint"})


@pytest.mark.parametrize(("change", "where", "words"), [
    ({"image": "a.png", "frames": None}, "points_frame", "is for a video"),
    ({"points": "auto"}, "points_frame", "give points"),
    ({"points": POINTS[:5]}, "points.p6", "all seven points"),
    ({"points": None, "frame_points": {"3": POINTS}}, "points_frame", "give points"),
])
def test_points_frame_refusals_name_the_field(change: dict, where: str, words: str) -> None:
    data = {**VIDEO, **change, "points_frame": 3}
    data = {k: v for k, v in data.items() if v is not None}
    with pytest.raises(ValidationError) as info:
        ScanSpec.model_validate(data)
    err = info.value.errors()[0]
    assert ".".join(map(str, err["loc"])) == where
    assert words in err["msg"]


def test_spec_import_stays_pydantic_only() -> None:
    code = ("import sys, prismcore.spec; "
            "print(any(m in sys.modules for m in ('numpy', 'cv2', 'scipy')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"

"""Bad reference points are refused with a message quoting them."""

from __future__ import annotations

import numpy as np
import pytest

from prismcore import InputError, ScanSpec, parse_points, run_scan

GOOD = "61,51 258,49 261,249 262,50 339,52"


@pytest.fixture
def image() -> np.ndarray:
    img = np.zeros((300, 400, 3), dtype=np.uint8)
    img[50:250, 60:260] = (200, 160, 90)
    img[50:250, 260:340] = (150, 120, 70)
    return img


@pytest.mark.parametrize(
    ("points", "message"),
    [
        ("61,51 258,49 261,249 262,50 839,52", "outside"),
        ("258,49 61,51 261,249 262,50 339,52", "not in order"),
        ("61,51 160,51 259,51 262,50 339,52", "collinear|closer than"),
        ("61,51 62,51 62,52 262,50 339,52", "closer than"),
        ("-40,51 258,49 261,249 262,50 339,52", "outside"),
    ],
)
@pytest.mark.parametrize("method", ["default", "paper"])
def test_bad_points(image, points, message, method):
    spec = ScanSpec(image="x", points=parse_points(points), method=method)
    with pytest.raises(InputError, match=message):
        run_scan(spec, image)


@pytest.mark.parametrize("text", ["1,2 3,4", "1,2 3,4 5,6 7,8 9,10 11,12", "a,b 1,2 3,4 5,6 7,8",
                                  "1;2 3,4 5,6 7,8 9,10"])
def test_parse_points_rejects(text):
    with pytest.raises(ValueError, match="point"):
        parse_points(text)


def test_parse_points_accepts_seven():
    ref = parse_points(GOOD + " 60,250 340,230")
    assert ref.p6 == (60.0, 250.0) and ref.p7 == (340.0, 230.0)


@pytest.mark.parametrize("tolerance", [-1, 129, float("nan")])
def test_absurd_tolerance(tolerance):
    with pytest.raises(ValueError, match="tolerance"):
        ScanSpec(image="x", points=parse_points(GOOD), tolerance=tolerance)


def test_pinhole_needs_focal():
    with pytest.raises(ValueError, match="focal"):
        ScanSpec(image="x", points=parse_points(GOOD), scale={"kind": "pinhole", "distance_mm": 5})


def test_schema_is_json_schema():
    schema = ScanSpec.model_json_schema()
    assert schema["type"] == "object" and "image" in schema["properties"]
    # the photo (or video) and its reference points: the same for every photo or frame, or per
    # frame of a video; or several views of one part, each with its photo and points
    # (a station's photo needs none: the station finds the part; auto_points alone is a search
    # as points "auto" is); each given and not null
    assert [option["required"] for option in schema["anyOf"]] == [
        ["image", "points"], ["image", "frame_points"], ["views"], ["image", "station"],
        ["image", "auto_points"]]
    for option in schema["anyOf"]:
        name = option["required"][-1]
        assert option["properties"] == {name: {"not": {"type": "null"}}}
        assert option["title"].startswith("Scan")  # a generated client's name for this way

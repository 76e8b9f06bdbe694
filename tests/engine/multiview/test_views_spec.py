"""The spec of several views of one part (`ScanSpec.views`) and of a video fitted as one box
(`fit` "joint"): each bad spec is refused by ONE error, at the field at fault, saying what is
wrong with it (not a field the user did not send, nor a rule of another kind of item)."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from prismcore import ScanSpec

SEVEN = [[20, 30], [120, 32], [118, 110], [120, 32], [170, 15], [22, 108], [165, 90]]
EDGE = {"kind": "edge", "edge": "width", "length_mm": 120}


def _views(n: int = 2, **extra: object) -> dict:
    return {"views": [{"image": f"view{k}.png", "points": SEVEN} for k in range(n)], "scale": EDGE, **extra}


def _only_error(spec: dict) -> tuple[tuple[str | int, ...], str]:
    with pytest.raises(ValidationError) as caught:
        ScanSpec.model_validate(spec)
    [error] = caught.value.errors()
    return tuple(error["loc"]), error["msg"]


# (the spec, where its one error is, words of the message)
BAD = {
    "no views": ({"views": []}, ("views",), "at least 2 views of the part, got 0"),
    "no views, a scale": (_views(0), ("views",), "at least 2 views of the part, got 0"),
    "one view": (_views(1), ("views",), "at least 2 views of the part, got 1"),
    "one view, no scale": ({"views": _views(1)["views"]}, ("views",), "got 1"),
    "views not a list": ({"views": "a.png", "scale": EDGE}, ("views",), "valid list"),
    "first view not a view": ({"views": ["a.png", _views(1)["views"][0]], "scale": EDGE}, ("views", 0),
                              "valid dictionary"),
    "first view without its photo": ({"views": [{"points": SEVEN}, *_views(1)["views"]], "scale": EDGE},
                                     ("views", 0, "image"), "Field required"),
    "other image": (_views(image="other.png"), ("image",), "is not the first view's 'view0.png'"),
    "points too": (_views(points=SEVEN), ("points",), "points does not go with views"),
    "image and points too": (_views(image="view0.png", points=SEVEN), ("points",),
                             "points does not go with views"),
    "points auto": (_views(points="auto"), ("points",),
                    "points \"auto\" does not go with views: each view carries its own seven points"),
    "points auto with a hint": (_views(points="auto", auto_points={"hint": [5, 5]}), ("points",),
                                "points \"auto\" does not go with views"),
    "auto_points alone": (_views(auto_points={"hint": [5, 5]}), ("auto_points",),
                          "each view carries its own seven points"),
    "side_image": (_views(side_image="side.png"), ("side_image",), "a side photo is another view"),
    "frames": (_views(frames={"every": 2}), ("frames",), "views are photos"),
    # what only a cloud uses: a joint fit makes none, so it would be silently ignored
    "RGB tolerance": (_views(tolerance=30), ("tolerance",), "RGB tolerance is the colour scan's"),
    "csv options": (_views(csv={"header": True}), ("csv",), "no cloud"),
    "ascii ply": (_views(ply_ascii=True), ("ply_ascii",), "no cloud"),
    "max_points": (_views(max_points=1000), ("max_points",), "no cloud"),
}


@pytest.mark.parametrize(("spec", "where", "words"), BAD.values(), ids=BAD.keys())
def test_a_bad_spec_with_views_has_one_error_at_the_field(spec: dict, where: tuple, words: str) -> None:
    loc, message = _only_error(spec)
    assert loc == where and words in message, (loc, message)


VIDEO = {"image": "clip.mp4", "fit": "joint", "scale": EDGE, "frame_points": {"3": SEVEN, "8": SEVEN}}


@pytest.mark.parametrize("name", ["tolerance", "csv", "ply_ascii", "max_points"])
def test_a_joint_video_refuses_the_clouds_options_too(name: str) -> None:
    value = {"tolerance": 30, "csv": {"colors": True}, "ply_ascii": True, "max_points": 1000}[name]
    loc, message = _only_error({**VIDEO, name: value})
    assert loc == (name,) and f"{name} does not go with fit \"joint\": " in message, message
    assert message.endswith("a joint fit writes its report (joint.json), no cloud"), message


@pytest.mark.parametrize("spec", [
    _views(),
    _views(image="view0.png", focal_px=900, max_pixels=10**7, nominal=[120, 80, 60], tolerance_mm=1),
    # a stored record reads back with every default written out
    json.loads(ScanSpec.model_validate(_views(3)).model_dump_json()),
    VIDEO,
], ids=["views", "what a joint fit uses", "stored record", "joint video"])
def test_what_a_joint_fit_uses_is_accepted(spec: dict) -> None:
    parsed = ScanSpec.model_validate(spec)
    assert parsed.image in ("view0.png", "clip.mp4")


def test_views_null_is_no_views_and_a_photo_needs_its_image() -> None:
    assert _only_error({"views": None, "points": SEVEN}) == (("image",), "Field required")

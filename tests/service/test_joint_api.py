"""Issue 20, item 1 at the API: an item with several views of one part (measured as ONE box), and a
video item with fit "joint": accepted as sent, and every bad input a 422 whose pointer names the
field at fault (the schema's rules, and at submit the uploads' recorded sizes and kinds).

In process (TestClient) on the real Redis and SeaweedFS; nobody consumes the queue here (the
worker's side is tests/service/test_joint_worker.py)."""

from __future__ import annotations

import warnings
from collections.abc import Iterator

import pytest
from prism_common.settings import get_settings

from prism_api.main import create_app
from prismcore.spec import JOINT_MAX_PIXELS, JOINT_MAX_VIEWS, ScanSpec

from .conftest import API_KEYS
from .test_api import photo

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "Using `httpx` with `starlette.testclient`")
    from fastapi.testclient import TestClient

ACME = {"X-API-Key": API_KEYS["acme"]}
# A box in a 256x128 photo: front p1 p2 p3 p6, right side p4 = p2, p5, p7.
SEVEN = [[20, 30], [120, 32], [118, 110], [120, 32], [170, 15], [22, 108], [165, 90]]
EDGE = {"kind": "edge", "edge": "width", "length_mm": 120}


@pytest.fixture
def client(settings, objects) -> Iterator[TestClient]:
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    with TestClient(app) as client:
        yield client


def _upload(client: TestClient, data: bytes, name: str = "view.png") -> str:
    r = client.post("/v1/uploads", files={"file": (name, data)}, headers=ACME)
    assert r.status_code in (200, 201), r.text
    reference: str = r.json()["reference"]
    return reference


@pytest.fixture
def refs(client) -> list[str]:
    """Three uploaded photos of one size (different bytes: three uploads)."""
    return [_upload(client, photo(size=2000 + k)) for k in range(3)]


def _views(refs: list[str], **extra) -> dict:
    return {"views": [{"image": r, "points": SEVEN} for r in refs], "scale": EDGE, **extra}


def _submit(client: TestClient, item: dict):
    return client.post("/v1/jobs", json={"items": [item]}, headers=ACME)


def test_an_item_with_views_is_accepted_and_stored_with_its_first_photo_as_image(client, refs, store):
    item = _views(refs, focal_px=900)
    item["views"][1] |= {"side_face": "right", "name": "from the left.jpg"}
    r = _submit(client, item)
    assert r.status_code == 202, r.text
    spec = store.get(r.json()["id"]).items[0].spec
    assert spec.image == refs[0] and [v.image for v in spec.views] == refs
    assert spec.views[1].name == "from the left.jpg" and spec.views[1].side_face == "right"
    assert ScanSpec.model_validate_json(spec.model_dump_json()) == spec  # the stored record reads back


def test_the_schema_says_views_replace_image_and_points(client):
    schema = client.get("/openapi.json").json()["components"]["schemas"]
    spec = schema["ScanSpec"]
    assert "image" not in spec.get("required", [])
    ways = [option["required"] for option in spec["anyOf"]]
    assert ["views"] in ways and ["image", "points"] in ways
    assert spec["properties"]["fit"]["anyOf"][0]["enum"] == ["frames", "joint"]
    assert set(schema["ViewSpec"]["required"]) == {"image", "points"}
    assert "joint" in schema["ResultPublic"]["properties"]
    assert {"views", "left_out"} <= set(schema["JointPublic"]["properties"])


# (what is changed in a good 3-view item, the pointer of the one error, a word of its detail)
BAD = {
    "no views": (lambda i, r: {"views": []}, "/items/0/views", "at least 2 views of the part, got 0"),
    "one view": (lambda i, r: {**i, "views": i["views"][:1]}, "/items/0/views", "at least 2 views"),
    "too many": (lambda i, r: {**i, "views": [i["views"][0]] * (JOINT_MAX_VIEWS + 1)}, "/items/0/views",
                 f"at most {JOINT_MAX_VIEWS} views"),
    "five points": (lambda i, r: _view(i, 1, points=SEVEN[:5]), "/items/0/views/1/points/5", "p6 is missing"),
    "no points": (lambda i, r: _view(i, 2, points=None), "/items/0/views/2/points", "Field required"),
    "auto points": (lambda i, r: _view(i, 1, points="auto"), "/items/0/views/1/points", "\"auto\" is not"),
    "bad side face": (lambda i, r: _view(i, 0, side_face="back"), "/items/0/views/0/side_face", "right"),
    "no scale": (lambda i, r: {k: v for k, v in i.items() if k != "scale"}, "/items/0/scale", "known edge"),
    "mm per px": (lambda i, r: {**i, "scale": {"kind": "mm_per_px", "front": 0.5}}, "/items/0/scale",
                  "known edge"),
    "other image": (lambda i, r: {**i, "image": r[1]}, "/items/0/image", "first view's"),
    "points too": (lambda i, r: {**i, "points": SEVEN}, "/items/0/points", "each view carries"),
    "points auto too": (lambda i, r: {**i, "points": "auto"}, "/items/0/points",
                        "points \"auto\" does not go with views"),
    "RGB tolerance": (lambda i, r: {**i, "tolerance": 30}, "/items/0/tolerance", "no cloud"),
    "formats": (lambda i, r: {**i, "formats": ["las"]}, "/items/0/formats", "no cloud"),
    "camera model": (lambda i, r: {**i, "principal_point": [128, 64]}, "/items/0/principal_point", "centre"),
    "fit frames": (lambda i, r: {**i, "fit": "frames"}, "/items/0/fit", "one box"),
    "unknown upload": (lambda i, r: _view(i, 1, image="upload:" + "0" * 32), "/items/0/views/1/image",
                       "no upload"),
    "same photo twice": (lambda i, r: _view(i, 2, image=r[0]), "/items/0/views/2/image",
                         "views.0's photo again"),
    "point outside": (lambda i, r: _view(i, 2, points=[*SEVEN[:2], [400, 110], *SEVEN[3:]]),
                      "/items/0/views/2/points/2", "p3"),
}


def _view(item: dict, k: int, **change) -> dict:
    views = [dict(v) for v in item["views"]]
    views[k] = {n: v for n, v in {**views[k], **change}.items() if v is not None}
    return {**item, "views": views}


@pytest.mark.parametrize("case", BAD.values(), ids=BAD.keys())
def test_bad_views_are_422_at_the_field(client, refs, case):
    change, where, words = case
    r = _submit(client, change(_views(refs), refs))
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == where and words in error["detail"], error


def test_views_of_different_sizes_are_refused_when_the_uploads_say_so(client, refs):
    other = _upload(client, photo(width=320, height=240), name="other.png")
    r = _submit(client, _views([refs[0], refs[1], other]))
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/views/2/image"
    assert "320x240 px, view 0's 256x128 px" in error["detail"] and "one image size" in error["detail"]


def test_a_video_is_no_view(client, refs):
    video = _upload(client, b"RIFF\x10\x00\x00\x00AVI " + b"\x00" * 64, name="clip.avi")
    r = _submit(client, _views([refs[0], video]))
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/views/1/image" and "a view is a photo" in error["detail"]


VIDEO_BAD = {
    "one frame": ({"frame_points": {"3": SEVEN}}, "/items/0/frame_points", "at least 2 frames"),
    "five points": ({"frame_points": {"3": SEVEN, "8": SEVEN[:5]}}, "/items/0/frame_points/8/5", "p6"),
    "same points": ({"points": SEVEN, "frames": {"every": 5}}, "/items/0/points", "frame_points"),
    "auto": ({"points": "auto", "frames": {"every": 5}}, "/items/0/points", "frame_points"),
    "pinhole": ({"frame_points": {"3": SEVEN, "8": SEVEN}, "focal_px": 500,
                 "scale": {"kind": "pinhole", "distance_mm": 400}}, "/items/0/scale", "known edge"),
}


@pytest.mark.parametrize("case", VIDEO_BAD.values(), ids=VIDEO_BAD.keys())
def test_bad_joint_videos_are_422_at_the_field(client, case):
    change, where, words = case
    video = _upload(client, b"RIFF\x10\x00\x00\x00AVI " + b"\x00" * 64, name="clip.avi")
    r = _submit(client, {"image": video, "fit": "joint", "scale": EDGE, **change})
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == where and words in error["detail"], error


def test_a_joint_video_and_fit_on_a_photo(client, refs):
    video = _upload(client, b"RIFF\x10\x00\x00\x00AVI " + b"\x00" * 64, name="clip.avi")
    ok = _submit(client, {"image": video, "fit": "joint", "scale": EDGE,
                          "frame_points": {"3": SEVEN, "8": SEVEN, "20": SEVEN}})
    assert ok.status_code == 202, ok.text
    r = _submit(client, {"image": refs[0], "points": SEVEN, "scale": EDGE, "fit": "joint"})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/items/0/points", r.text
    r = _submit(client, {"image": refs[0], "points": SEVEN, "fit": "frames"})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/items/0/fit", r.text


def test_the_default_formats_in_any_order_go_with_views(client, refs):
    r = _submit(client, _views(refs, formats=["ply", "csv"]))
    assert r.status_code == 202, r.text


def test_views_holding_more_pixels_than_a_joint_fit_takes_are_refused(client):
    # 7 photos of 8000x3000 px (168 MP; each within the per-photo limit): the fit holds them all.
    big = photo(width=8000, height=3000)
    refs = [_upload(client, photo(size=len(big) + k + 1, width=8000, height=3000)) for k in range(7)]
    assert 6 * 8000 * 3000 <= JOINT_MAX_PIXELS < 7 * 8000 * 3000
    r = _submit(client, _views(refs))
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/views" and "168 megapixels" in error["detail"], error
    assert _submit(client, _views(refs[:6])).status_code == 202

"""Uploads are probed when stored and jobs are checked against the probe at submit, in process
on the real Redis and SeaweedFS of the fixtures: what the probe says is checked against the
files as made here (size written, frames written, EXIF orientation set), and a point outside a
photo or out of order is refused at submit with a pointer to it."""

# ruff: noqa: F811 - `client` is test_api's fixture, imported to be used as such
from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

import cv2
import jsonschema
import numpy as np
import pytest
from PIL import Image

from .test_api import ACME, client, make_client, photo  # noqa: F401 (fixtures)

POINTS = {"p1": [10, 10], "p2": [110, 12], "p3": [108, 80], "p4": [150, 6], "p5": [200, 8]}


def jpeg(width: int, height: int, orientation: int = 1) -> bytes:
    out = io.BytesIO()
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.new("RGB", (width, height), (90, 120, 30)).save(out, "JPEG", exif=exif.tobytes())
    return out.getvalue()


def avi(tmp_path, frames: int, size: tuple[int, int]) -> bytes:
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, size)
    for i in range(frames):
        writer.write(np.full((size[1], size[0], 3), 20 * i, np.uint8))
    writer.release()
    return path.read_bytes()


def post(client, data: bytes, name: str):
    return client.post("/v1/uploads", files={"file": (name, data)}, headers=ACME)


@pytest.mark.parametrize(("data", "probe"), [
    (photo(0, 320, 200), {"format": "PNG", "width": 320, "height": 200}),
    (jpeg(300, 180), {"format": "JPEG", "width": 300, "height": 180}),
    (jpeg(300, 180, orientation=6), {"format": "JPEG", "width": 180, "height": 300}),  # turned
], ids=["png", "jpeg", "jpeg-exif-rotated"])
def test_photos_are_probed_as_the_engine_sees_them(client, store, data, probe):
    r = post(client, data, "photo.bin")  # the name says nothing: the content decides
    assert r.status_code == 201, r.text
    found = {k: v for k, v in r.json()["probe"].items() if v is not None}
    assert found == {"kind": "image", **probe}
    assert store.get_upload(r.json()["id"])["probe"]  # recorded with the upload


def test_videos_are_probed_with_their_frames(client, tmp_path):
    r = post(client, avi(tmp_path, 7, (96, 64)), "clip.avi")
    assert r.status_code == 201, r.text
    probe = r.json()["probe"]
    assert probe["kind"] == "video" and probe["format"] == "AVI" and probe["codec"] == "MJPG"
    assert (probe["frame_count"], probe["width"], probe["height"], probe["fps"]) == (7, 96, 64, 10.0)


def test_a_broken_video_is_recorded_not_refused(client):
    r = post(client, b"RIFF\x10\x00\x00\x00AVI junk" * 50, "junk.avi")
    assert r.status_code == 201, r.text
    probe = r.json()["probe"]
    assert probe["kind"] == "video" and probe["width"] is None and "'junk.avi'" in probe["error"]
    assert "/tmp" not in probe["error"]


@pytest.mark.parametrize(("data", "named"), [
    (b"just some notes\n" * 20, "text (text/plain)"),
    (b"%PDF-1.7\n%\xe2\xe3\xcf\xd3\n1 0 obj\n", "a PDF document (application/pdf)"),
    (b"GIF89a\x01\x00\x01\x00\x00\x00\x00;", "a GIF image (image/gif)"),
    (b'<?xml version="1.0"?>\n<svg xmlns="http://www.w3.org/2000/svg"/>', "an SVG drawing (image/svg+xml)"),
    (bytes(range(256)) * 4, "unrecognised binary data (application/octet-stream)"),
], ids=["text", "pdf", "gif", "svg", "binary"])
def test_neither_photo_nor_video_is_refused_and_not_kept(client, objects, store, data, named):
    before = set(objects.list_keys("uploads/"))
    r = post(client, data, "thing.jpg")
    assert r.status_code == 415, r.text
    body = r.json()
    assert body["type"] == "https://prismcloud.dev/problems/unsupported-media-type"
    assert body["detail"].startswith(f"'thing.jpg' is {named}") and body["detected_type"].startswith(named)
    assert set(objects.list_keys("uploads/")) == before  # deleted again


def _submit(client, items):
    return client.post("/v1/jobs", json={"items": items}, headers=ACME)


def _ref(client, data: bytes) -> str:
    r = post(client, data, "p.png")
    assert r.status_code == 201, r.text
    return r.json()["reference"]


@pytest.mark.parametrize(("points", "pointer", "words"), [
    ({**POINTS, "p5": [260, 8]}, "/items/1/points/p5", "point p5 (260,8) is outside the 256x128 image"),
    ({**POINTS, "p3": [108, 127.6]}, "/items/1/points/p3", "is outside the 256x128 image"),
    ({**POINTS, "p1": POINTS["p2"], "p2": POINTS["p1"]}, "/items/1/points", "not in order"),
    ([[10, 10], [110, 12], [108, 80], [150, 6], [300, 8]], "/items/1/points/4", "point p5"),  # a list
], ids=["right-of-photo", "below-photo", "swapped", "list"])
def test_points_the_engine_would_refuse_are_refused_at_submit(client, points, pointer, words):
    ref = _ref(client, photo())  # 256 x 128
    r = _submit(client, [{"image": ref, "points": POINTS}, {"image": ref, "points": points}])
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == pointer and words in error["detail"] and error["detail"].startswith("item 1: ")


def test_points_on_the_edge_pass(client):
    # The engine's limit: a point may lie up to half a pixel past the last pixel's centre.
    ref = _ref(client, photo())
    assert _submit(client, [{"image": ref, "points": {**POINTS, "p5": [255.5, 8]}}]).status_code == 202


def test_side_points_are_checked_against_the_side_photo(client):
    front, side = _ref(client, photo()), _ref(client, photo(0, 64, 64))
    two = {"image": front, "side_image": side, "focal_px": 500}
    inside = {**POINTS, "p4": [5, 5], "p5": [60, 6]}
    assert _submit(client, [{**two, "points": inside}]).status_code == 202
    r = _submit(client, [{**two, "points": {**inside, "p5": [150, 6]}}])  # in the front, not the side
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/items/0/points/p5", r.text


def test_video_frame_points_are_checked_against_the_frames(client, tmp_path):
    ref = _ref(client, avi(tmp_path, 3, (96, 64)))
    bad = {**POINTS, "p4": [50, 6], "p5": [90, 8], "p2": [40, 12], "p3": [40, 50], "p1": [10, 10]}
    good = {**bad, "p5": [90, 8]}
    assert _submit(client, [{"image": ref, "frame_points": {"1": good}}]).status_code == 202
    r = _submit(client, [{"image": ref, "frame_points": {"0": good, "2": {**bad, "p5": [120, 8]}}}])
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/items/0/frame_points/2/p5", r.text


def test_a_video_named_as_a_photo_and_a_photo_named_as_a_video_are_refused(client, tmp_path):
    video = post(client, avi(tmp_path, 5, (256, 128)), "clip.avi").json()["reference"]
    still = _ref(client, photo())
    r = _submit(client, [{"image": video, "points": POINTS}])
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/image" and "is a video" in error["detail"]
    r = _submit(client, [{"image": still, "points": POINTS, "frames": {"every": 2}}])
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/frames" and "is a photo, not a video" in error["detail"]


def test_frame_indices_past_the_end_are_refused_at_submit(client, tmp_path):
    video = post(client, avi(tmp_path, 5, (256, 128)), "five.avi").json()["reference"]
    r = _submit(client, [{"image": video, "points": POINTS, "frames": {"indices": [0, 4, 5, 9]}}])
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/frames/indices"
    assert "indices [5, 9] are past the video's end: it has 5 frames (0-4)" in error["detail"]
    r = _submit(client, [{"image": video, "frame_points": {"0": POINTS, "7": POINTS}}])
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/frame_points/7"
    ok = _submit(client, [{"image": video, "points": POINTS, "frames": {"indices": [0, 4]}}])
    assert ok.status_code == 202, ok.text


SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "box.jpg"


def _cut(data: bytes) -> bytes:
    return data[:40_000]


@pytest.mark.parametrize(("data", "fmt"), [
    (SAMPLE.read_bytes(), "JPEG"),
    (cv2.imencode(".png", cv2.imread(str(SAMPLE)))[1].tobytes(), "PNG"),
    (cv2.imencode(".webp", cv2.imread(str(SAMPLE)))[1].tobytes(), "WEBP"),
    (cv2.imencode(".jpg", cv2.imread(str(SAMPLE)), [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1].tobytes(), "JPEG"),
], ids=["jpeg", "png", "webp", "progressive-jpeg"])
def test_a_photo_cut_short_is_refused_as_truncated_and_not_kept(client, objects, data, fmt):
    # Its header is whole (the pixel size reads), the rest missing: the job would fail later.
    whole = post(client, data + b"appended after the image, as motion photos have" * 10, "whole.jpg")
    assert whole.status_code == 201 and whole.json()["probe"]["error"] is None, whole.text
    before = set(objects.list_keys("uploads/"))
    r = post(client, _cut(data), "cut.jpg")
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["type"] == "https://prismcloud.dev/problems/damaged-file" and body["truncated"] is True
    assert body["detail"].startswith(f"'cut.jpg' is a truncated {fmt} (40,000 bytes, cut short before"), body
    assert set(objects.list_keys("uploads/")) == before  # deleted again


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png(image: np.ndarray, *, interlaced: bool = False, cut: float = 1.0) -> bytes:
    """An RGB PNG written here (Adam7 when `interlaced`), its image data cut to `cut` of its
    zlib stream and its chunks closed properly after it (IDAT, IEND)."""
    h, w = image.shape[:2]
    passes = ([(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
               (0, 1, 1, 2)] if interlaced else [(0, 0, 1, 1)])
    raw = b"".join(b"\x00" + row.tobytes() for x0, y0, dx, dy in passes
                   for row in image[y0::dy, x0::dx] if row.size)
    data = zlib.compress(raw)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, int(interlaced)))
            + _chunk(b"IDAT", data[: int(len(data) * cut)]) + _chunk(b"IEND", b""))


def _pil_png(mode: str, **options) -> bytes:
    out = io.BytesIO()
    Image.effect_noise((301, 203), 60).convert(mode).save(out, "PNG", **options)
    return out.getvalue()


NOISE = np.random.default_rng(7).integers(0, 256, (203, 301, 3), dtype=np.uint8)


@pytest.mark.parametrize("data", [
    _png(NOISE), _png(NOISE, interlaced=True), _png(NOISE[:5, :3], interlaced=True),
    _pil_png("L"), _pil_png("P"), _pil_png("1"), _pil_png("RGBA"), _pil_png("LA"),
    cv2.imencode(".png", NOISE.astype(np.uint16) * 257)[1].tobytes(),
    cv2.imencode(".png", cv2.imread(str(SAMPLE)))[1].tobytes(),
], ids=["rgb", "adam7", "adam7-5x3", "grey", "palette", "1-bit", "rgba", "grey-alpha", "16-bit", "sample"])
def test_a_whole_png_of_any_kind_is_taken(client, data):
    # Its image data inflates to as many bytes as its header's pixels take, however they are laid out.
    assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) is not None
    r = post(client, data, "whole.png")
    assert r.status_code == 201 and r.json()["probe"]["format"] == "PNG", r.text


@pytest.mark.parametrize(("cut", "interlaced"), [(0.5, False), (0.98, False), (0.0, False), (0.6, True)],
                         ids=["half", "most", "none", "adam7"])
def test_a_png_whose_image_data_is_cut_short_is_refused_and_not_kept(client, objects, cut, interlaced):
    """Its chunks whole and closed (an IEND after a short IDAT): the pixels it holds are fewer
    than its header announces, so the job would fail later; refused as a truncated JPEG is."""
    data = _png(NOISE, interlaced=interlaced, cut=cut)
    assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) is None  # OpenCV cannot read it
    before = set(objects.list_keys("uploads/"))
    r = post(client, data, "cut.png")
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["type"] == "https://prismcloud.dev/problems/damaged-file" and body["truncated"] is True
    assert body["detail"].startswith(f"'cut.png' is a truncated PNG ({len(data):,} bytes, its image data "
                                     "cut short: "), body
    assert set(objects.list_keys("uploads/")) == before  # deleted again


def _pil(image: np.ndarray, fmt: str, **options) -> bytes:
    out = io.BytesIO()
    Image.fromarray(image).save(out, fmt, **options)
    return out.getvalue()


# Every other photo format the upload takes, as OpenCV and Pillow write them: the TIFFs with their
# image directory after the pixels (OpenCV) and before them (Pillow), strips plain or compressed.
OTHER_FORMATS = {
    "bmp-opencv": (cv2.imencode(".bmp", NOISE)[1].tobytes(), "BMP"),
    "bmp-pillow": (_pil(NOISE, "BMP"), "BMP"),
    "bmp-grey": (_pil(NOISE[..., 0], "BMP"), "BMP"),
    "tiff-opencv": (cv2.imencode(".tiff", NOISE)[1].tobytes(), "TIFF"),
    "tiff-pillow": (_pil(NOISE, "TIFF"), "TIFF"),
    "tiff-lzw": (_pil(NOISE, "TIFF", compression="tiff_lzw"), "TIFF"),
    "tiff-jpeg": (_pil(NOISE, "TIFF", compression="jpeg"), "TIFF"),
    "webp": (cv2.imencode(".webp", NOISE)[1].tobytes(), "WEBP"),
}


@pytest.mark.parametrize("kind", OTHER_FORMATS)
def test_every_other_format_cut_short_is_refused_and_whole_is_taken(client, objects, kind):
    """Issue 37: a cut BMP or TIFF was stored and its job failed later; like a JPEG, PNG or WebP
    it is refused at upload now, by the bytes its header points to."""
    data, fmt = OTHER_FORMATS[kind]
    r = post(client, data, f"whole.{fmt.lower()}")
    assert r.status_code == 201 and r.json()["probe"]["format"] == fmt, r.text
    for cut in (0.95, 0.5):
        short = data[: int(len(data) * cut)]
        before = set(objects.list_keys("uploads/"))
        r = post(client, short, f"cut.{fmt.lower()}")
        assert r.status_code == 422, (cut, r.text)
        body = r.json()
        assert body["type"] == "https://prismcloud.dev/problems/damaged-file" and body["truncated"] is True
        said = f"'cut.{fmt.lower()}' is a truncated {fmt} ({len(short):,} bytes"
        assert body["detail"].startswith(said), body
        assert set(objects.list_keys("uploads/")) == before  # not kept


def test_a_png_over_the_pixel_limit_is_not_inflated_at_upload(make_client):
    # A decompression bomb costs the API nothing: past PRISM_MAX_PIXELS its data is not read (the
    # worker refuses the photo as too large), so its pixels are not counted either.
    r = post(make_client(max_pixels=10_000), _png(NOISE, cut=0.5), "big.png")
    assert r.status_code == 201 and r.json()["probe"]["width"] == 301, r.text


def _published_body_schema(client) -> jsonschema.Draft202012Validator:
    """The validator of POST /v1/jobs' body, as the OpenAPI document the API serves publishes it."""
    document = client.get("/openapi.json").json()
    body = document["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    return jsonschema.Draft202012Validator({**body, "components": document["components"]})


FRAME_KEYS_TAKEN = [["0", "4"], ["007", "11"], ["3"], ["0", "00", "000"], [str(k) for k in range(12)]]
FRAME_KEYS_REFUSED = ["+3", " 3", "3 ", "3.0", "1_0", "-1", "x", "", "\u0663"]


def test_frame_points_keys_the_published_schema_allows_are_taken(client, tmp_path):
    """The schema names frame_points' keys as the API reads them (digits only, propertyNames):
    every body it allows is taken (202), every key it refuses is refused at that key (422)."""
    schema = _published_body_schema(client)
    frame_points = schema.schema["components"]["schemas"]["ScanSpec"]["properties"]["frame_points"]
    assert {"pattern": "^[0-9]+$"} in [o.get("propertyNames") for o in frame_points["anyOf"]], frame_points
    video = post(client, avi(tmp_path, 12, (256, 128)), "twelve.avi").json()["reference"]
    for keys in FRAME_KEYS_TAKEN:
        body = {"items": [{"image": video, "frame_points": dict.fromkeys(keys, POINTS)}]}
        assert schema.is_valid(body), keys
        r = client.post("/v1/jobs", json=body, headers=ACME)
        assert r.status_code == 202, (keys, r.text)
    for key in FRAME_KEYS_REFUSED:
        body = {"items": [{"image": video, "frame_points": {"1": POINTS, key: POINTS}}]}
        assert not schema.is_valid(body), key
        r = client.post("/v1/jobs", json=body, headers=ACME)
        assert r.status_code == 422, (key, r.text)
        assert f"/items/0/frame_points/{key}" in [e["pointer"] for e in r.json()["errors"]], (key, r.json())

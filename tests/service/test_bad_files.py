"""Bad photos through the whole service (API, worker, object store): truncated, corrupt and
mislabelled files, a decompression bomb, an image over the pixel limit, a region of zero pixels.
Each one fails its own item with a message naming the file or the reason; the good item beside it
succeeds; no call answers 5xx and no worker dies. A photo cut short is refused at upload.
"""

from __future__ import annotations

import struct
import zlib

import cv2
import pytest

from prismsynth import Box, render_clip, write_video

from .faultstack import FaultStack, item, png, tiny_scene

MAX_PIXELS = 100_000  # the service's limit in this module: a 400x300 photo is over it


def _bomb(width: int = 100_000, height: int = 100_000) -> bytes:
    """A valid-looking PNG of a few hundred bytes that declares width x height RGB pixels."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    rows = zlib.compress(b"\x00" * (1 + 3 * 64) * 64, 9)  # the first rows' worth of zeros
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", rows) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    stack = FaultStack(tmp_path_factory.mktemp("badfiles"), PRISM_MAX_PIXELS=str(MAX_PIXELS),
                       PRISM_TILES_PER_FACE="1")
    yield stack
    stack.stop()


SCENE = tiny_scene(1)
GOOD = png(SCENE.image)
ok, JPEG = cv2.imencode(".jpg", cv2.cvtColor(SCENE.image, cv2.COLOR_RGB2BGR))
JPEG = JPEG.tobytes()
BIG = png(cv2.resize(SCENE.image, (400, 300)))

# name -> (file name, bytes, a piece the item's error must hold)
CASES = {
    "corrupt-middle": ("bits.png", GOOD[:200] + bytes(b ^ 0x5A for b in GOOD[200:400]) + GOOD[400:],
                       "'bits.png'"),
    "decompression-bomb": ("bomb.png", _bomb(), "'bomb.png'"),
    "over-pixel-limit": ("big.png", BIG, "'big.png'"),
}


# name -> (file name, bytes, what the refusal must call it): neither a photo nor a video, so
# refused at upload (415) and not stored.
REFUSED = {
    "random-bytes": ("noise.jpg", bytes(range(256)) * 20, "application/octet-stream"),
    "text-as-png": ("notes.png", b"these are not pixels\n" * 40, "text/plain"),
    "gif": ("anim.png", b"GIF89a\x01\x00\x01\x00\x00\x00\x00;" * 3, "image/gif"),
    "svg": ("vector.png", b'<svg xmlns="http://www.w3.org/2000/svg" width="9" height="9"/>', "image/svg+xml"),
}


# name -> (file name, bytes, the format named): a photo whose header reads but whose data stops
# short of its end, refused at upload (422 damaged-file) and not stored.
CUT = {
    "truncated-png": ("cut.png", GOOD[: len(GOOD) // 2], "PNG"),
    "truncated-jpeg": ("cut.jpg", JPEG[: len(JPEG) * 2 // 3], "JPEG"),
    "png-header-only": ("head.png", GOOD[:40], "PNG"),
}


@pytest.mark.parametrize("case", sorted(CUT))
def test_a_photo_cut_short_is_refused_at_upload(stack, case, figures):
    name, data, fmt = CUT[case]
    r = stack.call("POST", "/v1/uploads", files={"file": (name, data)})
    figures["inputs tried"] += 1
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    assert r.json()["type"].endswith("/damaged-file"), r.text
    assert r.json()["detail"].startswith(f"{name!r} is a truncated {fmt} ({len(data):,} bytes"), r.text


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_not_a_photo_is_refused_at_upload(stack, case, figures):
    name, data, expected = REFUSED[case]
    r = stack.call("POST", "/v1/uploads", files={"file": (name, data)})
    figures["inputs tried"] += 1
    assert r.status_code == 415 and r.headers["content-type"] == "application/problem+json", r.text
    assert f"{name!r} is " in r.json()["detail"] and expected in r.json()["detail"], r.text


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_file_fails_its_item_only(stack, case, figures):
    name, data, expected = CASES[case]
    bad, good = stack.upload(data, name=name), stack.upload(GOOD)
    job_id = stack.submit([item(bad, SCENE), item(good, SCENE)])
    job = stack.wait([job_id])[job_id]
    figures["inputs tried"] += 1
    assert job["state"] == "completed_with_failures" and job["items_failed"] == 1, job
    failed, fine = job["items"]
    assert failed["state"] == "failed" and expected in failed["error"], failed
    assert "\n" not in failed["error"] and "Traceback" not in failed["error"]
    assert fine["state"] == "succeeded" and fine["result"]["points"] > 0
    if case == "over-pixel-limit":
        assert f"{MAX_PIXELS}" in failed["error"].replace(",", "").replace("_", "")


def test_mislabelled_but_readable_files_are_read_by_content(stack, figures):
    refs = [stack.upload(JPEG, name="photo.png"), stack.upload(GOOD, name="photo.jpg")]
    job_id = stack.submit([item(r, SCENE) for r in refs])
    job = stack.wait([job_id])[job_id]
    figures["inputs tried"] += 2
    assert [i["state"] for i in job["items"]] == ["succeeded", "succeeded"], job


def test_points_the_engine_would_refuse_are_refused_at_submit(stack, figures):
    # Five clicks on one pixel: the photo's size is known from its upload, so the job is refused
    # at once (422 pointing at the points) instead of failing when polled.
    spec = {**item(stack.upload(GOOD), SCENE), "points": [[60, 60]] * 5}
    r = stack.call("POST", "/v1/jobs", json={"items": [spec]})
    figures["inputs tried"] += 1
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    [error] = r.json()["errors"]
    assert error["pointer"] == "/items/0/points" and "closer than 4 px" in error["detail"], error


def test_collinear_front_points_are_refused_at_submit_in_words(stack):
    points = [[20, 60], [80, 60], [140, 60], [80, 60], [100, 40]]  # P1, P2, P3 on one row
    spec = {**item(stack.upload(GOOD), SCENE), "points": points}
    r = stack.call("POST", "/v1/jobs", json={"items": [spec]})
    assert r.status_code == 422, r.text
    [error] = r.json()["errors"]
    assert "to one line" in error["detail"], error
    print(f"\nzero-pixel region: {error['detail']}")


def test_empty_file_is_refused_at_upload(stack, figures):
    r = stack.call("POST", "/v1/uploads", files={"file": ("empty.png", b"")})
    figures["inputs tried"] += 1
    assert r.status_code == 422 and "empty" in r.text.lower(), r.text


# -- video files ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> tuple[list, bytes]:
    scenes = render_clip(Box(120.0, 80.0, 60.0), 4, image_size=(160, 128), focal_px=175.0, seed=3)
    path = tmp_path_factory.mktemp("clip") / "clip.avi"
    write_video((s.image for s in scenes), path, codec="MJPG")
    return scenes, path.read_bytes()


def _video_item(reference: str, scene) -> dict:
    return {**item(reference, scene), "frames": {"every": 1}}


VIDEO_CASES = {  # name -> (file name, how to spoil the clip)
    "truncated": ("cut.avi", lambda v: v[: len(v) // 2]),
    "header-only": ("head.avi", lambda v: v[:300]),
    "corrupt-middle": ("bits.avi", lambda v: v[:2000] + bytes(b ^ 0x5A for b in v[2000:6000]) + v[6000:]),
    "riff-junk": ("junk.avi", lambda v: b"RIFF\x10\x00\x00\x00AVI junk" * 50),
    "mp4-junk": ("junk.mp4", lambda v: b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 8),
    # A photo given frames (and indices past a video's end) is refused at submit now, from the
    # upload's probe: test_upload_probe.py.
    "clip-named-png": ("clip.png", lambda v: v),
}


@pytest.mark.parametrize("case", sorted(VIDEO_CASES))
def test_bad_video_fails_its_item_only_or_reads_what_is_there(stack, clip, case, figures):
    # A cut or damaged clip may still hold whole frames: the item then measures those. Either
    # way nothing crashes, the error names the file, and the good photo beside it succeeds.
    scenes, video = clip
    name, spoil = VIDEO_CASES[case]
    bad, good = stack.upload(spoil(video), name=name), stack.upload(GOOD)
    job_id = stack.submit([_video_item(bad, scenes[0]), item(good, SCENE)])
    job = stack.wait([job_id])[job_id]
    figures["inputs tried"] += 1
    spoilt, fine = job["items"]
    assert job["state"] == ("succeeded" if spoilt["state"] == "succeeded" else "completed_with_failures"), job
    assert fine["state"] == "succeeded"
    if spoilt["state"] == "failed":
        assert f"'{name}'" in spoilt["error"] or name in spoilt["error"], spoilt["error"]
        assert "\n" not in spoilt["error"] and "/tmp" not in spoilt["error"]
    else:
        assert spoilt["state"] == "succeeded" and spoilt["result"]["points"] > 0, spoilt
    if case in ("riff-junk", "mp4-junk", "header-only"):
        assert spoilt["state"] == "failed", spoilt
    if case == "clip-named-png":  # read by content, not by name
        assert spoilt["state"] == "succeeded", spoilt


def test_a_video_with_nothing_to_measure_fails_its_item_only(stack, clip, tmp_path, figures):
    scenes, _ = clip
    path = tmp_path / "empty.avi"  # a well-formed AVI that holds no frame at all
    cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48)).release()
    bad = {**_video_item(stack.upload(path.read_bytes(), name="empty.avi"), scenes[0])}
    needle = "'empty.avi'"
    job_id = stack.submit([bad, item(stack.upload(GOOD), SCENE)])
    job = stack.wait([job_id])[job_id]
    figures["inputs tried"] += 1
    spoilt, fine = job["items"]
    # one item failed, one measured: the job says so (not plain "succeeded")
    assert job["state"] == "completed_with_failures" and fine["state"] == "succeeded", job
    assert spoilt["state"] == "failed" and needle in spoilt["error"], spoilt
    assert "/tmp" not in spoilt["error"]


def test_no_worker_died(stack):
    for worker in stack.workers:  # the bad files were refused, not crashed on: never restarted
        assert worker.proc is not None and worker.proc.poll() is None
        assert worker.log.count(" ready.") == 1
        assert "WorkerLostError" not in worker.log and "exited with" not in worker.log

"""What the API adds for the web page: the preview relay and the page itself (in process, against
the real Redis and SeaweedFS of the fixtures)."""

from __future__ import annotations

import os
import tempfile

import cv2
import numpy as np
import pytest
from prism_common.records import FrameRecord, State

from prism_api.webapp import CSP, NOT_BUILT, STATIC_DIR, mount_web

from .test_api import ACME, GLOBEX, item, make_client, submit, upload  # noqa: F401 (make_client: fixture)


@pytest.fixture
def api(request):
    """A TestClient of the app on the test's settings (test_api's `make_client`)."""
    return request.getfixturevalue("make_client")()


def _job_with_preview(api, store, objects, data: bytes) -> str:
    """A job whose first item succeeded with a preview object holding `data`; the second failed."""
    job_id = submit(api, [item(upload(api)), item(upload(api))]).json()["id"]
    record = store.get(job_id)
    key = f"jobs/{job_id}/items/0/preview.ply"
    objects.put_bytes(key, data)
    store.put_item(job_id, record.items[0].model_copy(update={"state": State.succeeded,
                                                              "outputs": {"preview": key}}))
    store.put_item(job_id, record.items[1].model_copy(update={"state": State.failed, "error": "x"}))
    return job_id


@pytest.mark.parametrize("size", [0, 1000, 3 * (1 << 20) + 17], ids=["empty", "small", "chunks"])
def test_preview_round_trip(api, store, objects, size):
    data = os.urandom(size)
    job_id = _job_with_preview(api, store, objects, data)
    r = api.get(f"/v1/jobs/{job_id}/items/0/preview.ply", headers=ACME)
    assert r.status_code == 200, r.text
    assert r.content == data
    assert r.headers["Content-Length"] == str(size)
    assert r.headers["Content-Type"] == "application/octet-stream"


def test_preview_is_the_tenants_only(api, store, objects):
    job_id = _job_with_preview(api, store, objects, b"ply\n")
    path = f"/v1/jobs/{job_id}/items/0/preview.ply"
    theirs = api.get(path, headers=GLOBEX)
    assert theirs.status_code == 404 and theirs.json()["detail"] == f"no job {job_id!r}"
    assert api.get(path).status_code == 401
    assert api.get(path, headers={"X-API-Key": "nope"}).status_code == 401


@pytest.mark.parametrize(("index", "words"), [(1, "has no preview (the item is failed)"),
                                              (2, "has no item 2"), (-1, None)])
def test_preview_of_a_missing_item_or_preview(api, store, objects, index, words):
    job_id = _job_with_preview(api, store, objects, b"ply\n")
    r = api.get(f"/v1/jobs/{job_id}/items/{index}/preview.ply", headers=ACME)
    assert r.status_code == (404 if words else 422)
    if words:
        assert words in r.json()["detail"]


def test_preview_object_gone_is_404(api, store, objects):
    job_id = _job_with_preview(api, store, objects, b"ply\n")
    objects.client.delete_object(Bucket=objects.bucket, Key=f"jobs/{job_id}/items/0/preview.ply")
    r = api.get(f"/v1/jobs/{job_id}/items/0/preview.ply", headers=ACME)
    assert r.status_code == 404 and "is gone" in r.json()["detail"]


def _clip() -> bytes:
    """A small real MJPEG AVI (8 frames, 256x128): the job's item must name a video."""
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "clip.avi")
        writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (256, 128))
        for i in range(8):
            writer.write(np.full((128, 256, 3), 20 * i, np.uint8))
        writer.release()
        with open(path, "rb") as fh:
            return fh.read()


def _video_job_with_frame_preview(api, store, objects, data: bytes) -> str:
    """A video item whose frame 4 succeeded with a preview holding `data`; frame 6 failed."""
    job_id = submit(api, [item(upload(api, _clip(), name="clip.avi"), frames={"every": 2})]).json()["id"]
    key = f"jobs/{job_id}/items/0/frame_000004/preview.ply"
    objects.put_bytes(key, data)
    store.put_frame(job_id, 0, FrameRecord(index=4, state=State.succeeded, outputs={"preview": key}))
    store.put_frame(job_id, 0, FrameRecord(index=6, state=State.failed, error="x"))
    return job_id


def test_frame_preview_round_trip_and_its_refusals(api, store, objects):
    data = os.urandom(70_000)
    job_id = _video_job_with_frame_preview(api, store, objects, data)
    path = f"/v1/jobs/{job_id}/items/0/frames/{{}}/preview.ply"
    r = api.get(path.format(4), headers=ACME)
    assert r.status_code == 200 and r.content == data and r.headers["Content-Length"] == str(len(data))
    item_preview = api.get(f"/v1/jobs/{job_id}/items/0/preview.ply", headers=ACME)
    assert item_preview.status_code == 404  # the video item has none of its own
    theirs = api.get(path.format(4), headers=GLOBEX)
    assert theirs.status_code == 404 and theirs.json()["detail"] == f"no job {job_id!r}"
    for frame, words in ((6, "frame 6 of item 0 of job {} has no preview (the frame is failed)"),
                         (2, "item 0 of job {} has no frame 2 (yet)")):
        r = api.get(path.format(frame), headers=ACME)
        assert r.status_code == 404 and r.json()["detail"] == words.format(job_id)
    assert api.get(path.format(-1), headers=ACME).status_code == 422
    assert api.get(f"/v1/jobs/{job_id}/items/1/frames/4/preview.ply", headers=ACME).status_code == 404


def test_home_redirects_to_the_page(api):
    r = api.get("/", follow_redirects=False)
    assert r.status_code == 307 and r.headers["Location"] == "app/"  # relative: kept under a proxy prefix


def test_the_built_page_is_served_with_its_policy(api):
    # As the web tests do: an unbuilt page is a failed setup, not a reason to skip.
    assert (STATIC_DIR / "index.html").is_file(), f"the page is not built in {STATIC_DIR}: run scripts/setup"
    r = api.get("/app/")
    assert r.status_code == 200 and r.headers["Content-Type"].startswith("text/html")
    assert r.headers["Content-Security-Policy"] == CSP and r.headers["Cache-Control"] == "no-cache"
    asset = next(p for p in (STATIC_DIR / "assets").iterdir() if p.suffix == ".js")
    assert f"./assets/{asset.name}" in r.text  # relative, like every asset path
    js = api.get(f"/app/assets/{asset.name}")
    assert js.status_code == 200 and js.content == asset.read_bytes()
    assert "immutable" in js.headers["Cache-Control"]
    assert api.get("/app/assets/nothing.js").status_code == 404


def test_without_a_build_the_page_says_how_to_build_it(tmp_path):
    from fastapi import FastAPI

    from .test_api import TestClient

    app = FastAPI()
    mount_web(app, tmp_path)  # an empty folder: nothing built
    r = TestClient(app).get("/app/")
    assert r.status_code == 404 and r.text == NOT_BUILT


@pytest.mark.parametrize(("stored", "media"), [("overlay.jpg", "image/jpeg"), ("overlay.png", "image/png")],
                         ids=["jpeg", "png-from-before"])
@pytest.mark.parametrize("route", ["overlay.jpg", "overlay.png"])
def test_overlay_is_served_under_both_names_with_its_own_type(api, store, objects, stored, media, route):
    # The worker stores overlay.jpg; a job from before the overlay was a JPEG has overlay.png.
    # Both routes answer either, with the type of what is stored (old links keep working).
    ok, encoded = cv2.imencode(os.path.splitext(stored)[1], np.full((16, 24, 3), 90, np.uint8))
    assert ok
    data = encoded.tobytes()
    job_id = submit(api, [item(upload(api))]).json()["id"]
    record = store.get(job_id)
    key = f"jobs/{job_id}/items/0/{stored}"
    objects.put_bytes(key, data)
    store.put_item(job_id, record.items[0].model_copy(update={"state": State.succeeded,
                                                              "outputs": {"overlay": key}}))
    r = api.get(f"/v1/jobs/{job_id}/items/0/{route}", headers=ACME)
    assert r.status_code == 200, r.text
    assert r.content == data and r.headers["Content-Type"] == media


@pytest.mark.parametrize("route", ["overlay.jpg", "overlay.png"])
def test_a_frames_overlay_under_both_names(api, store, objects, route):
    job_id = submit(api, [item(upload(api, _clip(), name="clip.avi"), frames={"every": 2})]).json()["id"]
    data = cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))[1].tobytes()
    key = f"jobs/{job_id}/items/0/frame_000004/overlay.jpg"
    objects.put_bytes(key, data)
    store.put_frame(job_id, 0, FrameRecord(index=4, state=State.succeeded, outputs={"overlay": key}))
    store.put_frame(job_id, 0, FrameRecord(index=6, state=State.failed, error="x"))
    r = api.get(f"/v1/jobs/{job_id}/items/0/frames/4/{route}", headers=ACME)
    assert r.status_code == 200 and r.content == data and r.headers["Content-Type"] == "image/jpeg"
    missing = api.get(f"/v1/jobs/{job_id}/items/0/frames/6/{route}", headers=ACME)
    assert missing.status_code == 404 and "has no overlay (the frame is failed)" in missing.json()["detail"]

"""The part's CAD files through the whole service (API under uvicorn, a Celery worker, redis-server
and SeaweedFS): an item asking for step and drawing gets part.step, part.step.json and the
drawing's SVG, PDF and DXF as downloads, stored with their media types, the STEP read back by
OpenCascade at the reported size, the Python client saving them under their names; an item
asking for step without a scale is refused at submit with a 422 problem."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from xml.etree import ElementTree as ET

import cv2
import ezdxf
import httpx
import pytest
from pypdf import PdfReader

from prism_cli.client import ApiClient
from prism_cli.stack import start_api, start_worker
from prismsynth import Box, render_oblique_view

from .conftest import API_KEYS
from .servers import service_env

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
ACME = {"X-API-Key": API_KEYS["acme"]}
MEDIA = {"step": "model/step", "step_meta": "application/json", "drawing_svg": "image/svg+xml",
         "drawing_pdf": "application/pdf", "drawing_dxf": "image/vnd.dxf"}


@pytest.fixture(scope="module")
def stack(redis_server, s3_server, tmp_path_factory) -> Iterator[httpx.Client]:
    tmp = tmp_path_factory.mktemp("cad")
    env = service_env(redis_server.port, s3_server.port, db=10, bucket="cad-e2e")
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=1)
    http = httpx.Client(base_url=f"http://127.0.0.1:{api.port}", timeout=30, headers=ACME)
    yield http
    http.close()
    worker.stop()
    api.stop()


@pytest.fixture(scope="module")
def item(stack) -> dict:
    scene = render_oblique_view(BOX, seed=1)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, 92])
    assert ok
    r = stack.post("/v1/uploads", files={"file": ("box.jpg", data.tobytes())})
    assert r.status_code in (200, 201), r.text
    return {"image": r.json()["reference"], "points": [list(map(round, scene.points[n])) for n in NAMES],
            "focal_px": scene.focal_px, "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}}


@pytest.fixture(scope="module")
def job(stack, item) -> dict:
    r = stack.post("/v1/jobs", json={"items": [{**item, "formats": ["step", "drawing"],
                                                "nominal": [120, 80, 60], "tolerance_mm": 3}]})
    assert r.status_code == 202, r.text
    for _ in range(720):
        done = stack.get(f"/v1/jobs/{r.json()['id']}").json()
        if done["state"] not in ("queued", "running"):
            assert done["state"] == "succeeded", done
            return done
        time.sleep(0.25)
    raise AssertionError(f"job not final: {done}")


def test_the_item_downloads_the_solid_and_the_drawing_with_their_media_types(job, tmp_path):
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.STEPControl import STEPControl_Reader

    downloads = job["items"][0]["downloads"]
    assert set(downloads) == {*MEDIA, "preview", "overlay", "report"}
    files = {}
    for kind, media in MEDIA.items():
        r = httpx.get(downloads[kind])
        assert r.status_code == 200 and r.headers["content-type"] == media, (kind, r.headers)
        files[kind] = r.content
    report = httpx.get(downloads["report"]).json()
    w, h, d = (report["dimensions"][k] for k in ("width", "height", "depth"))
    (tmp_path / "part.step").write_bytes(files["step"])
    reader = STEPControl_Reader()
    reader.ReadFile(str(tmp_path / "part.step"))
    reader.TransferRoots()
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(reader.OneShape(), box, False, False)
    lo, hi = box.CornerMin(), box.CornerMax()
    assert (lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z()) == pytest.approx((0, 0, 0, w, h, d), abs=1e-6)
    meta = json.loads(files["step_meta"])
    assert meta["dimensions"]["depth"]["value_mm"] == d and meta["verdict"] == report["quality"]["verdict"]
    verdict = report["quality"]["dimensions"]["width"]["verdict"]
    shown = f"{w:.3f} ± {report['uncertainty']['width']:.3f} {verdict}"
    svg = ET.fromstring(files["drawing_svg"])
    assert shown in [t.text for t in svg.iter("{http://www.w3.org/2000/svg}text")]
    (tmp_path / "drawing.pdf").write_bytes(files["drawing_pdf"])
    assert shown in PdfReader(tmp_path / "drawing.pdf").pages[0].extract_text()
    (tmp_path / "drawing.dxf").write_bytes(files["drawing_dxf"])
    doc = ezdxf.readfile(tmp_path / "drawing.dxf")
    assert not doc.audit().has_errors
    assert shown in [dim.dxf.text for dim in doc.modelspace().query("DIMENSION")]


def test_the_python_client_saves_them_under_their_names(stack, job, tmp_path):
    with ApiClient(str(stack.base_url), API_KEYS["acme"]) as client:
        saved = client.download(client.job(job["id"]), tmp_path)
    names = {p.name for p in saved}
    assert {"part.step", "part.step.json", "drawing.svg", "drawing.pdf", "drawing.dxf"} <= names
    assert (tmp_path / "item-0" / "part.step").read_bytes().startswith(b"ISO-10303-21;")


@pytest.mark.parametrize("fmt", ["step", "drawing"])
def test_without_a_scale_the_submit_is_refused_with_a_problem(stack, item, fmt):
    unscaled = {k: v for k, v in item.items() if k != "scale"}
    r = stack.post("/v1/jobs", json={"items": [{**unscaled, "formats": [fmt]}]})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    body = r.json()
    assert body["type"].endswith("/validation")
    assert f"format '{fmt}' is in mm or metres, but without a scale" in body["detail"], body
    assert body["errors"][0]["pointer"].startswith("/items/0"), body


def test_a_joint_fit_of_two_photos_downloads_its_solid_and_drawing(stack, tmp_path):
    from prismsynth import photo_like_views

    scenes = photo_like_views(2, 2)
    views = []
    for k, p in enumerate(scenes):
        ok, data = cv2.imencode(".png", cv2.cvtColor(p.image, cv2.COLOR_RGB2BGR))
        assert ok
        r = stack.post("/v1/uploads", files={"file": (f"view{k + 1}.png", data.tobytes())})
        assert r.status_code in (200, 201), r.text
        clicks = [[float(p.clicks[f"p{i}"][0]), float(p.clicks[f"p{i}"][1])] for i in range(1, 8)]
        views.append({"image": r.json()["reference"], "name": f"view{k + 1}.png", "points": clicks})
    edge = {"kind": "edge", "edge": scenes[0].known_edge, "length_mm": scenes[0].known_length_mm}
    item = {"views": views, "scale": edge, "formats": ["step", "drawing"]}
    r = stack.post("/v1/jobs", json={"items": [item]})
    assert r.status_code == 202, r.text
    for _ in range(720):
        job = stack.get(f"/v1/jobs/{r.json()['id']}").json()
        if job["state"] not in ("queued", "running"):
            break
        time.sleep(0.25)
    assert job["state"] == "succeeded", job
    downloads = job["items"][0]["downloads"]
    assert set(downloads) == {"joint", *MEDIA}
    joint = httpx.get(downloads["joint"]).json()
    meta = httpx.get(downloads["step_meta"]).json()
    assert {d: meta["dimensions"][d]["value_mm"] for d in ("width", "height", "depth")} == {
        d: joint["dimensions"][d] for d in ("width", "height", "depth")}
    assert meta["photo"] == "2 views: view1.png, view2.png" and meta["frame"] == "box"
    step = httpx.get(downloads["step"])
    assert step.headers["content-type"] == "model/step" and step.content.startswith(b"ISO-10303-21;")

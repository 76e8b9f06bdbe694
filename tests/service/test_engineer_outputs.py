"""Issue 13 through the whole service (API under uvicorn, a Celery worker, redis-server and
SeaweedFS): LAZ and glb outputs downloaded and read back with laspy and pygltflib, the items'
verdicts against a nominal size and the job's counts of them, an operator's default formats
(PRISM_DEFAULT_FORMATS set to laz + glb: those with a scale, csv + ply without), the job's results
table as CSV and JSON, and `prism results` / `prism download` on it.
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Iterator

import cv2
import httpx
import laspy
import numpy as np
import pygltflib
import pytest

from prism_cli.main import main
from prism_cli.stack import start_api, start_worker
from prismcore import run_scan
from prismcore.io.images import load_image
from prismcore.outputs.writers import write_format
from prismcore.report import report_dict
from prismsynth import Box, render_oblique_view

from .conftest import API_KEYS
from .servers import service_env
from .worker_env import as_stored

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
ACME = {"X-API-Key": API_KEYS["acme"]}


class Stack:
    def __init__(self, port: int) -> None:
        self.url = f"http://127.0.0.1:{port}"
        self.http = httpx.Client(base_url=self.url, timeout=30, headers=ACME)

    def upload(self, data: bytes) -> str:
        r = self.http.post("/v1/uploads", files={"file": ("box.jpg", data)})
        assert r.status_code in (200, 201), r.text
        return r.json()["reference"]

    def run(self, items: list[dict], timeout: float = 180) -> dict:
        r = self.http.post("/v1/jobs", json={"items": items, "client_reference": "lot 42"})
        assert r.status_code == 202, r.text
        job_id = r.json()["id"]
        for _ in range(int(timeout / 0.25)):
            job = self.http.get(f"/v1/jobs/{job_id}").json()
            if job["state"] in ("succeeded", "completed_with_failures", "failed", "cancelled"):
                return job
            time.sleep(0.25)
        raise AssertionError(f"job {job_id} not final: {job}")


@pytest.fixture(scope="module")
def stack(redis_server, s3_server, tmp_path_factory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("engineer")
    # The compact formats as the deployment's default (the service's own is csv + ply): laz + glb
    # where there is a scale.
    env = service_env(redis_server.port, s3_server.port, db=9, bucket="engineer-e2e",
                      DEFAULT_FORMATS='["laz", "glb"]')
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=2)
    made = Stack(api.port)
    yield made
    made.http.close()
    worker.stop()
    api.stop()


@pytest.fixture(scope="module")
def scene():
    return render_oblique_view(BOX, seed=1)


@pytest.fixture(scope="module")
def photo(scene) -> bytes:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, 92])
    assert ok
    return data.tobytes()


def _item(reference: str, scene, **extra) -> dict:
    return {"image": reference, "points": [list(map(round, scene.points[n])) for n in NAMES],
            "focal_px": scene.focal_px,
            "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}, **extra}


@pytest.fixture(scope="module")
def finished(stack, scene, photo) -> tuple[dict, list[dict]]:
    """One job: laz+glb asked for with a true nominal; the operator's defaults with a nominal
    30 mm too wide; and an item without a scale (so no metric formats, and no nominal)."""
    ref = stack.upload(photo)
    items = [_item(ref, scene, formats=["laz", "glb"], nominal=[BOX.width_mm, BOX.height_mm, BOX.depth_mm],
                   tolerance_mm=2.0),
             _item(ref, scene, nominal=[BOX.width_mm + 30, BOX.height_mm, BOX.depth_mm],
                   tolerance_mm=[1, 1, 1]),
             {k: v for k, v in _item(ref, scene).items() if k != "scale"}]
    job = stack.run(items)
    assert job["state"] == "succeeded", job
    assert [i["state"] for i in job["items"]] == ["succeeded"] * 3, job
    return job, items


def test_laz_and_glb_download_and_read_back_as_the_engine_writes_them(finished, photo):
    job, items = finished
    item = job["items"][0]
    assert set(item["downloads"]) == {"laz", "glb", "preview", "overlay", "report"}
    spec = as_stored(items[0])  # the service's default spacing applied
    local = run_scan(spec, load_image(photo))
    laz = httpx.get(item["downloads"]["laz"]).content
    las = laspy.read(io.BytesIO(laz))
    assert len(las.points) == item["result"]["points"] == len(local.cloud.points)
    # LAS axes: (x, y, z) = (x, z, -y) / 1000 of the engine's mm, at 0.1 mm resolution.
    expected = np.stack([local.cloud.points[:, 0], local.cloud.points[:, 2], -local.cloud.points[:, 1]],
                        axis=1) / 1000.0
    got = np.stack([las.x, las.y, las.z], axis=1)
    np.testing.assert_allclose(got, expected, atol=1e-4)  # one LAS step: 0.1 mm
    np.testing.assert_array_equal(np.asarray(las.red) // 257, local.cloud.colors[:, 0])

    glb = httpx.get(item["downloads"]["glb"]).content
    model = pygltflib.GLTF2.load_from_bytes(glb)
    assert len(model.meshes) >= 1 and len(model.images) >= 1 and len(model.textures) >= 1
    positions = [a for a in model.accessors if a.max is not None and len(a.max) == 3]
    span = np.max([a.max for a in positions], axis=0) - np.min([a.min for a in positions], axis=0)
    dims = item["result"]["dimensions"]
    np.testing.assert_allclose(sorted(span * 1000), sorted([dims["width"], dims["height"], dims["depth"]]),
                               rtol=1e-3)
    buf = io.BytesIO()
    write_format("glb", buf, local.cloud, spec, report=local.report, images=[load_image(photo)])
    assert glb == buf.getvalue()  # the very model the engine makes of this photo


def test_default_formats_apply_only_where_the_spec_names_none(finished):
    job, _ = finished
    assert set(job["items"][1]["downloads"]) == {"laz", "glb", "preview", "overlay", "report"}
    # No scale: the metric defaults cannot apply, the item gets csv and ply.
    assert set(job["items"][2]["downloads"]) == {"csv", "ply", "preview", "overlay", "report"}


def test_verdicts_per_item_and_counted_on_the_job(stack, finished, photo):
    job, items = finished
    local = run_scan(as_stored(items[0]), load_image(photo))
    first, wide, plain = (i["result"]["quality"] for i in job["items"])
    assert first == report_dict(local.report)["quality"] and first["verdict"] in ("pass", "uncertain")
    assert wide["verdict"] == "fail" and wide["dimensions"]["width"]["verdict"] == "fail"
    assert wide["dimensions"]["width"]["deviation_mm"] == pytest.approx(-30, abs=2)
    assert plain is None
    expected = {"pass": 0, "fail": 1, "uncertain": 0} | {first["verdict"]: 1}
    assert job["verdicts"] == expected
    cheap = stack.http.get(f"/v1/jobs/{job['id']}", params={"item_limit": 0}).json()
    assert cheap["verdicts"] == expected and cheap["items"] == []


def test_results_table_as_csv_and_json(stack, finished):
    job, items = finished
    r = stack.http.get(f"/v1/jobs/{job['id']}/results.csv")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    doc = stack.http.get(f"/v1/jobs/{job['id']}/results.json").json()
    assert doc["verdicts"] == job["verdicts"] and doc["client_reference"] == "lot 42"
    assert len(rows) == len(doc["rows"]) == 3
    for row, item, spec in zip(rows, job["items"], items, strict=True):
        result = item["result"]
        assert (row["input"], row["state"], row["client_reference"]) == (spec["image"], "succeeded", "lot 42")
        for d in ("width", "height", "depth"):
            assert float(row[d]) == result["dimensions"][d]
        assert int(row["cloud_points"]) == result["points"]
        assert [float(row["p1_x"]), float(row["p1_y"])] == spec["points"][0]
        assert row["points_source"] == "clicked"
        assert row["verdict"] == ((result["quality"] or {}).get("verdict") or "")
        assert row["file_name"] == "box.jpg" and row["item_reference"] == "" and row["error"] == ""
        assert row["warnings"] == " | ".join(result["warnings"])
    assert doc["rows"][1]["width_verdict"] == "fail"
    assert "in pixels, not mm" in doc["rows"][2]["warnings"]  # no scale: warned, and the table says so
    missing = stack.http.get("/v1/jobs/" + "0" * 32 + "/results.csv")
    assert missing.status_code == 404
    assert missing.headers["content-type"] == "application/problem+json"
    other = stack.http.get(f"/v1/jobs/{job['id']}/results.json",
                           headers={"X-API-Key": API_KEYS["globex"]})
    assert other.status_code == 404


def test_results_table_names_the_file_sent_the_item_s_reference_and_a_failure_in_words(stack, scene, photo):
    """Issue 38: a row joins back to what the client sent (the upload's file name, the item's own
    reference) and a failed item's row says why in words."""
    r = stack.http.post("/v1/uploads", files={"file": ("part 7.jpg", photo)})
    assert r.status_code in (200, 201), r.text
    ref = r.json()["reference"]
    too_long = stack.http.post("/v1/jobs", json={"items": [{**_item(ref, scene), "reference": "x" * 201}]})
    assert too_long.status_code == 422 and "/items/0/reference" in too_long.text, too_long.text
    job = stack.run([{**_item(ref, scene), "reference": "part-7"},
                     {**_item(ref, scene, max_points=1000), "reference": "=part-8"}])
    assert job["state"] == "completed_with_failures", job
    rows = list(csv.DictReader(io.StringIO(stack.http.get(f"/v1/jobs/{job['id']}/results.csv").text)))
    doc = stack.http.get(f"/v1/jobs/{job['id']}/results.json").json()
    assert [(r["file_name"], r["item_reference"], r["input"], r["state"]) for r in rows] == [
        ("part 7.jpg", "part-7", ref, "succeeded"), ("part 7.jpg", "'=part-8", ref, "failed")]
    assert doc["rows"][1]["item_reference"] == "=part-8"  # the JSON keeps it as sent
    failed = doc["rows"][1]
    assert failed["error"] == job["items"][1]["error"] and "max_points" in failed["error"], failed
    assert failed["width"] is None and failed["points_source"] == "clicked" and failed["warnings"] is None
    assert doc["rows"][0]["width"] == job["items"][0]["result"]["dimensions"]["width"]


def test_prism_results_and_download(stack, finished, capsys, tmp_path):
    job, _ = finished
    args = ["--api", stack.url, "--key", API_KEYS["acme"]]
    assert main(["results", job["id"], *args]) == 0
    printed = capsys.readouterr().out
    assert "FAIL" in printed and "lot 42" in printed and "clicked" in printed
    assert main(["download", job["id"], "--out", str(tmp_path), *args]) == 0
    table = (tmp_path / "results.csv").read_bytes()
    assert table == stack.http.get(f"/v1/jobs/{job['id']}/results.csv").content
    assert (tmp_path / "item-0" / "cloud.laz").is_file() and (tmp_path / "item-0" / "box.glb").is_file()
    assert main(["results", "f" * 32, *args]) == 2
    assert "404" in capsys.readouterr().err

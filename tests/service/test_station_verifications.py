"""A station verified through the service: POST /v1/stations/{id}/verifications (the reference
part's photos, its size and tolerance, measured by the API as `prism station verify` measures
them), its history (GET), the station's summary stating its status and capability, the Python
client and `prism station verify --remote`; and the items measured on the station afterwards,
through the whole stack (uvicorn, a Celery worker, redis-server, SeaweedFS), each stating its
station's verification and the camera's drift in its result and in results.csv.

The photos are the example station's (`prism sample --station`: the sample's camera and board,
the 70 x 45 x 30 mm reference placed 7 times), the station calibrated with its true camera.
"""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import anyio
import cv2
import httpx
import numpy as np
import pytest
import redis
from prism_common.settings import get_settings

from prism_api.main import create_app
from prism_cli.client import ApiClient
from prism_cli.sample_command import reference_placements, turned
from prism_cli.stack import start_api, start_worker
from prismcore.camera import CameraModel
from prismcore.station import calibrate_station
from prismcore.station.board import default_board
from prismsynth.station import StationSetup, station_scene, station_setup

from .conftest import API_KEYS
from .servers import service_env

DB = 6
BUCKET = "t-verifications"
ACME = {"X-API-Key": API_KEYS["acme"]}
GLOBEX = {"X-API-Key": API_KEYS["globex"]}
PRISM = str(Path(sys.executable).with_name("prism"))
SAMPLE_SEED = 11  # prism sample --station's setup


def _jpeg(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    return data.tobytes()


@pytest.fixture(scope="module")
def setup() -> StationSetup:
    return station_setup(SAMPLE_SEED, board=default_board())


@pytest.fixture(scope="module")
def station_doc(setup) -> dict:
    plate = station_scene(SAMPLE_SEED, setup, parts=0).plate
    w, h = setup.image_size
    camera = CameraModel(fx=setup.K[0, 0], fy=setup.K[1, 1], cx=setup.K[0, 2], cy=setup.K[1, 2],
                         dist=[float(v) for v in setup.dist], image_width=w, image_height=h)
    station = calibrate_station(setup.board, plate, camera=camera, plate=plate)
    return dict(json.loads(station.model_dump_json()))


@pytest.fixture(scope="module")
def placements(setup) -> list[tuple[str, bytes]]:
    """The reference part's 7 placements, as `prism sample --station` renders them."""
    return [(f"reference-{i}.jpg", _jpeg(station_scene(100 + i, setup, box=box).photo))
            for i, box in enumerate(reference_placements(setup), 1)]


def _form(photos: list[tuple[str, bytes]], reference: str | None = "70,45,30",
          tolerance: str | None = "2") -> dict:
    data = {k: v for k, v in (("reference", reference), ("tolerance", tolerance)) if v is not None}
    return {"files": [("photo", p) for p in photos], "data": data}


def _app(settings):
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    return app


def test_a_verification_is_stored_with_its_station_and_listed(settings, station_doc, placements):
    """Verified at +-2 mm (the renders' biases under 10 % of 2T), stated in the station's summary and
    station.json; a wrong reference (72 mm) is not verified, and both are in the history, newest first."""
    app = _app(settings)

    async def run() -> dict[str, httpx.Response]:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://testserver",
                                     timeout=300, headers=ACME) as http:
            made = await http.post("/v1/stations", json=station_doc)
            sid = made.json()["id"]
            got = {"made": made}
            got["ok"] = await http.post(f"/v1/stations/{sid}/verifications", **_form(placements))
            got["summary_ok"] = await http.get(f"/v1/stations/{sid}")
            got["document"] = await http.get(f"/v1/stations/{sid}/station.json")
            got["wrong"] = await http.post(f"/v1/stations/{sid}/verifications",
                                           **_form(placements, reference="72,45,30"))
            got["summary_wrong"] = await http.get(f"/v1/stations/{sid}")
            got["history"] = await http.get(f"/v1/stations/{sid}/verifications")
            got["foreign"] = await http.get(f"/v1/stations/{sid}/verifications", headers=GLOBEX)
            got["foreign_post"] = await http.post(f"/v1/stations/{sid}/verifications", headers=GLOBEX,
                                                  **_form(placements))
            return got

    got = anyio.run(run)
    made = got["made"].json()
    assert made["verification"]["status"] == "not verified" and made["verification"]["date"] is None
    cap = made["capability"]
    assert 0 < cap["mm_per_px"]["near"] < cap["mm_per_px"]["far"] < 1 and cap["min_part_mm"] > 0, cap
    ok = got["ok"]
    assert ok.status_code == 201, ok.text
    done = ok.json()
    assert done["verified"] is True and done["decided_by"] == [] and len(done["photos"]) == 7
    assert done["photos"][0] == "reference-1.jpg" and done["tolerance_mm"] == 2.0
    for name, dim in done["dimensions"].items():
        assert abs(dim["bias_mm"]) <= 0.4 and dim["grr_percent"] < 30, (name, dim)
        assert all(dim["within_3_sigma"]), (name, dim)
    status = got["summary_ok"].json()["verification"]
    assert status["status"] == "verified" and status["text"].startswith("verified on "), status
    assert status["bias_mm"]["width"] == pytest.approx(done["dimensions"]["width"]["bias_mm"], abs=1e-3)
    assert json.loads(got["document"].content)["verification"]["verified"] is True
    wrong = got["wrong"]
    assert wrong.status_code == 201 and wrong.json()["verified"] is False, wrong.text
    assert any(d.startswith("width: ") for d in wrong.json()["decided_by"])
    assert got["summary_wrong"].json()["verification"]["status"] == "not verified"
    history = got["history"].json()["verifications"]
    assert [v["id"] for v in history] == [wrong.json()["id"], done["id"]]
    assert got["foreign"].status_code == 404 and got["foreign_post"].status_code == 404


@pytest.mark.parametrize(("form", "pointer", "says"), [
    ({"count": 3}, "/photo", "3 placements: a verification needs 5 at least"),
    ({"reference": "70x45x30"}, "/reference", "expected W,D,H in mm"),
    ({"reference": None}, "/reference", "missing"),
    ({"tolerance": "0"}, "/tolerance", "expected T > 0"),
    ({"tolerance": "abc"}, "/tolerance", "expected T > 0"),
    ({"same": True}, "/photo", "centres lie 0 mm (RMS) from their mean"),
    ({"broken": True}, "/photo/2", ""),
])
def test_bad_verifications_are_refused_at_their_field_and_nothing_stored(settings, station_doc, placements,
                                                                         form, pointer, says):
    app = _app(settings)
    photos = placements[:form.get("count", 7)]
    if form.get("same"):
        photos = [placements[2]] * 5
    if form.get("broken"):
        photos = [*placements[:2], ("broken.jpg", b"not a photo"), *placements[3:]]
    body = _form(photos, reference=form.get("reference", "70,45,30"), tolerance=form.get("tolerance", "2"))

    async def run() -> tuple[httpx.Response, httpx.Response]:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://testserver",
                                     timeout=300, headers=ACME) as http:
            sid = (await http.post("/v1/stations", json=station_doc)).json()["id"]
            return (await http.post(f"/v1/stations/{sid}/verifications", **body),
                    await http.get(f"/v1/stations/{sid}/verifications"))

    answer, history = anyio.run(run)
    assert answer.status_code == 422, answer.text
    problem = answer.json()
    assert problem["errors"][0]["pointer"] == pointer and says in problem["detail"], problem
    assert history.json()["verifications"] == []


def test_other_bodies_are_refused(settings, station_doc, placements):
    app = _app(settings)

    async def run() -> list[httpx.Response]:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://testserver",
                                     timeout=60, headers=ACME) as http:
            sid = (await http.post("/v1/stations", json=station_doc)).json()["id"]
            return [
                await http.post(f"/v1/stations/{sid}/verifications", json={"reference": "70,45,30"}),
                await http.post(f"/v1/stations/{sid}/verifications",
                                files=[("photo", placements[0]), ("extra", ("x.txt", b"x"))],
                                data={"reference": "70,45,30"}),
                await http.post(f"/v1/stations/{'f' * 32}/verifications", **_form(placements[:1])),
                await http.get(f"/v1/stations/{'f' * 32}/verifications"),
            ]

    json_body, extra, unknown, unknown_list = anyio.run(run)
    assert json_body.status_code == 415, json_body.text
    assert extra.status_code == 422 and extra.json()["errors"][0]["pointer"] == "/extra", extra.text
    assert unknown.status_code == 404 and unknown_list.status_code == 404


@pytest.fixture(scope="module")
def stack(redis_server, s3_server, tmp_path_factory) -> Iterator[str]:
    redis.Redis(port=redis_server.port, db=DB).flushdb()
    tmp = tmp_path_factory.mktemp("verifications")
    env = service_env(redis_server.port, s3_server.port, db=DB, bucket=BUCKET)
    api = start_api(tmp / "api", env)
    worker = start_worker(tmp / "worker", env, concurrency=1)
    yield f"http://127.0.0.1:{api.port}"
    worker.stop()
    api.stop()


def test_client_cli_remote_and_items_state_the_verification(stack, station_doc, placements, setup, tmp_path):
    """The Python client and `prism station verify --remote` verify the service's station; its items
    then state "verified" and the camera's shift in their result and results.csv; a station whose
    last verification failed states "not verified", warned."""
    photos = []
    for name, data in placements:
        photos.append(tmp_path / name)
        photos[-1].write_bytes(data)
    part = tmp_path / "part.jpg"
    part.write_bytes(_jpeg(station_scene(23, setup, max_size_mm=150).photo))
    moved = tmp_path / "moved.jpg"  # the reference after the camera turned 10 px, as the sample's moved.jpg
    moved.write_bytes(_jpeg(station_scene(5003, turned(setup, 10.0), box=reference_placements(setup)[2],
                                          nudge=False).photo))
    env = {"PRISM_API_URL": stack, "PRISM_API_KEY": API_KEYS["acme"], "PATH": "/usr/bin:/bin",
           "HOME": str(tmp_path), "COLUMNS": "200"}
    with ApiClient(stack, API_KEYS["acme"]) as client:
        made = client.create_station(station_doc)
        done = client.verify_station(made.id, photos, (70, 45, 30), tolerance=2)
        assert done.verified and client.station(made.id).verification.status == "verified"
        items = [{"image": client.upload(part)}, {"image": client.upload(moved)}]
        job = client.wait(client.submit({"items": items}, station=made.id).id, timeout=300)
        result = job.items[0].result
        assert job.state == "succeeded" and result is not None and result.station is not None, job
        assert result.station.verification.status == "verified", result.station
        assert result.station.verification.text.startswith(f"verified on {done.date:%Y-%m-%d}: bias ")
        assert result.station.drift.moved is False and result.station.drift.shift_px < 4
        assert not any("not verified" in w for w in result.warnings), result.warnings
        knocked = job.items[1].result
        assert knocked is not None and knocked.station is not None, job
        assert knocked.station.verification.status == "verified before the camera moved", knocked.station
        assert knocked.station.drift.moved is True and 9 <= knocked.station.drift.shift_px <= 11
        assert any("before the camera moved" in w for w in knocked.warnings), knocked.warnings
        rows = list(csv.DictReader(io.StringIO(httpx.get(f"{stack}/v1/jobs/{job.id}/results.csv",
                                                         headers=ACME).text)))
        assert rows[0]["station_verification"] == "verified" and float(rows[0]["camera_shift_px"]) < 4
        assert rows[0]["station_verification_date"] == f"{done.date:%Y-%m-%d}", rows[0]
        assert rows[1]["station_verification"] == "verified before the camera moved", rows[1]
        assert 9 <= float(rows[1]["camera_shift_px"]) <= 11 and rows[1]["station_verification_date"]
        # --remote: a wrong reference, not verified (exit 1), stored: the items say so
        run = subprocess.run([PRISM, "station", "verify", "--remote", made.id, "--reference", "72,45,30",
                              "--tolerance", "2", *map(str, photos)], env=env, capture_output=True, text=True,
                             timeout=300)
        assert run.returncode == 1, run.stdout + run.stderr
        assert "\nnot verified on " in run.stdout
        assert f"stored with station {made.id} on the service" in run.stdout
        assert [v.verified for v in client.station_verifications(made.id)] == [False, True]
        job = client.wait(client.submit({"items": [{"image": client.upload(part)}]}, station=made.id).id,
                          timeout=300)
        result = job.items[0].result
        assert result is not None and result.station is not None
        assert result.station.verification.status == "not verified"
        assert any(w.startswith("the station is not verified: its verification on ") for w in result.warnings)
        rows = list(csv.DictReader(io.StringIO(httpx.get(f"{stack}/v1/jobs/{job.id}/results.csv",
                                                         headers=ACME).text)))
        assert rows[0]["station_verification"] == "not verified" and rows[0]["station_reverify"] == "False"
    run = subprocess.run([PRISM, "station", "verify", "--remote", made.id, "--reference", "70,45,30",
                          "--tolerance", "2", *map(str, photos)], env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0 and "\nverified on " in run.stdout, run.stdout + run.stderr

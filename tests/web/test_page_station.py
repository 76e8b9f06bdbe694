"""Station mode in the page, against the real stack: a station stored from its station.json
through the page (listed with its camera, board, plane fit and plate), a folder of photos dropped
on it (a file that is not a photo left out), ONE job with an item per photo and nothing else, its
table with each part's width, height and depth within max(2 %, 1.5 mm) of the rendered box, the
empty support refused "no part found" and two parts "2 parts found: one part per photo", and a
part's fit on the photo opened from its row. The service calibrates a station from its photos
sent through the page, and refuses a bad board.json and a plane photo without the board in
words, at the file at fault; a station is deleted from its row. Screenshots go to
test-artifacts/web/.

The photos are `prismsynth.station` renders of one station setup (as tests/service/
test_stations.py makes them), calibrated with the true camera from one plate; a few photos only,
for CI's time."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from page_driver import PageDriver
from playwright.sync_api import expect

from prismcore.camera import CameraModel
from prismcore.station import calibrate_station
from prismsynth.station import StationSetup, calibration_views, station_scene, station_setup

ARTEFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "web"
SIZE = (1280, 1024)
LAPTOP = {"width": 1366, "height": 768}
SETUP_SEED = 3
TIMES = "\N{MULTIPLICATION SIGN}"
# The folder: (seed, parts on the support) a photo: three parts, the empty support between them
# (a refusal mid-batch) and two parts on it; the refusals' words.
PARTS = {"part-1.jpg": (101, 1), "part-2.jpg": (102, 1), "part-3.jpg": (200, 0), "part-4.jpg": (104, 1),
         "part-5.jpg": (205, 2)}
REFUSED = {"part-3.jpg": "no part found", "part-5.jpg": "2 parts found: one part per photo"}


def _jpeg(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    return data.tobytes()


def _shot(page, name: str) -> None:
    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTEFACTS / name), full_page=True)


@pytest.fixture(scope="module")
def setup() -> StationSetup:
    return station_setup(SETUP_SEED, image_size=SIZE)


@pytest.fixture(scope="module")
def station_json(setup, tmp_path_factory) -> Path:
    """station.json as `prism station calibrate --camera ... --plate ...` writes it."""
    plate = station_scene(100, setup).plate
    w, h = setup.image_size
    camera = CameraModel(fx=setup.K[0, 0], fy=setup.K[1, 1], cx=setup.K[0, 2], cy=setup.K[1, 2],
                         dist=[float(v) for v in setup.dist], image_width=w, image_height=h)
    station = calibrate_station(setup.board, plate, camera=camera, plate=plate)
    path = tmp_path_factory.mktemp("station") / "station.json"
    path.write_text(station.model_dump_json())
    return path


@pytest.fixture(scope="module")
def folder(setup, tmp_path_factory) -> tuple[Path, dict[str, dict[str, float] | None]]:
    """A folder of photos as a line camera leaves it, and each photo's true dimensions (None:
    refused)."""
    root = tmp_path_factory.mktemp("line") / "batch"
    root.mkdir()
    truth: dict[str, dict[str, float] | None] = {}
    for name, (seed, parts) in PARTS.items():
        scene = station_scene(seed, setup, parts=parts)
        (root / name).write_bytes(_jpeg(scene.photo))
        truth[name] = scene.box.dimensions if parts == 1 and scene.box else None
    (root / "notes.txt").write_text("shift 2\n")
    return root, truth


def _station_mode(page) -> PageDriver:
    d = PageDriver(page)
    d.log_in()
    page.get_by_label("Station", exact=True).check()
    expect(page.locator("#station-section")).to_be_visible()
    expect(page.locator("#stage")).to_be_hidden()  # the photo to mark is the other mode's
    expect(page.locator("#station-status")).to_contain_text("station")  # the list was read
    return d


def _store(page, station_json: Path, name: str) -> None:
    details = page.locator("#new-station")
    if details.get_attribute("open") is None:
        page.get_by_text("Add a station").click()
    page.get_by_label("Name (optional)").fill(name)
    page.get_by_label("station.json").set_input_files(str(station_json))
    page.get_by_role("button", name="Store the station").click()
    expect(page.locator("#station-status")).to_contain_text(f"Stored {name}")


def _rows(page) -> list[dict[str, str]]:
    return page.evaluate("""() => [...document.querySelectorAll('#results-table tbody tr')].map(tr =>
        Object.fromEntries([...tr.querySelectorAll('td[data-col]')]
          .map(td => [td.dataset.col, td.textContent])))""")


def _value(cell: str) -> tuple[float, float]:
    found = re.fullmatch(r"([\d.]+) ± ([\d.]+) mm( ⚠)?", cell.strip())  # ⚠: a warning is about it
    assert found, cell
    return float(found[1]), float(found[2])


def test_a_station_and_a_folder_of_photos_measured_in_one_job(page, station_json, folder):
    root, truth = folder
    _station_mode(page)
    _store(page, station_json, "line 1")
    doc = json.loads(station_json.read_text())
    row = page.locator("#stations tbody tr", has_text="line 1").first
    expect(row).to_contain_text(f"1280 {TIMES} 1024 px")
    expect(row).to_contain_text(f"ChArUco, 9 {TIMES} 6 squares of 40 mm")
    expect(row).to_contain_text(f"{doc['plane']['rms_px']:.2f} px RMS")
    expect(row).to_contain_text("stored")
    expect(page.get_by_label("Use line 1", exact=False).first).to_be_checked()

    # On a laptop's first screen: the station chosen and where to drop the photos.
    page.set_viewport_size(LAPTOP)
    page.evaluate("window.scrollTo(0, 0)")
    for where in (row, page.get_by_text("choose a folder"), page.locator("#station-submit")):
        box = where.bounding_box()
        assert box and box["y"] + box["height"] <= LAPTOP["height"], (where, box)
    _shot(page, "station-first-screen.png")

    # The folder, as the folder picker gives it: every photo, the notes left out.
    page.locator("#station-folder").set_input_files(str(root))
    summary = page.locator("#station-photos-summary")
    expect(summary).to_contain_text("5 photos · all uploaded")
    expect(summary).to_contain_text("1 other file left out (batch/notes.txt)")
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        page.get_by_role("button", name="Measure 5 photos on line 1").click()
    body = sent.value.post_data_json
    station_id = page.locator("#stations tbody tr.current").get_attribute("data-station")
    assert [set(i) for i in body["items"]] == [{"image", "station"}] * len(PARTS), body
    assert {i["station"] for i in body["items"]} == {station_id}

    expect(page.locator("#job-state")).to_contain_text("Done, with failures:", timeout=300_000)
    expect(page.locator("#job-state")).to_contain_text(
        f"2 of {len(PARTS)} scans failed, the others were measured.")
    expect(page.locator("#results-table tbody tr")).to_have_count(len(PARTS))
    rows = {r["input"]: r for r in _rows(page)}
    assert set(rows) == {f"batch/{name}" for name in PARTS}, rows
    for name, dims in truth.items():
        r = rows[f"batch/{name}"]
        if dims is None:
            assert r["state"].startswith(f"failed: {REFUSED[name]}"), r
            assert not r["width"] and not r["height"] and not r["depth"], r
            continue
        assert r["state"] == "succeeded", r
        for d, true in dims.items():
            value, sigma = _value(r[d])
            assert abs(value - true) <= max(0.02 * true, 1.5), (name, d, value, true)
            assert sigma > 0, (name, d, sigma)  # the engine's 1 sigma, shown beside each value
    # A figure a warning is about is flagged in the table as in the result: part 2's width is
    # seen on its top face only, says its warning.
    warned = rows["batch/part-2.jpg"]
    assert "width" in warned["warnings"] and warned["width"].endswith("⚠"), warned
    _shot(page, "station-table.png")

    # A part's fit on the photo, opened from its row: the overlay of that item, shown large.
    index = list(PARTS).index("part-2.jpg")
    with page.expect_response(re.compile(rf"/items/{index}/overlay\.jpg$")) as got:
        page.get_by_role("button", name=f"Open scan {index + 1} in the result").click()
    assert got.value.status == 200
    overlay = page.locator("#overlay")
    expect(overlay).to_be_visible()
    expect(page.locator("#overlay-figure")).to_have_class(re.compile(r"\blarge\b"))
    assert overlay.evaluate("img => img.naturalWidth") > 0
    assert overlay.bounding_box()["width"] > 500  # large enough to check the fit by eye
    expect(page.locator("#details")).to_contain_text("on the station")
    for d in truth["part-2.jpg"]:
        expect(page.locator(f"#dimensions dd[data-field={d}]")).to_contain_text(" ± ")
    _shot(page, "station-overlay.png")
    # The refused photo opened: its reason, and no other part's fit left on screen.
    empty = list(PARTS).index("part-3.jpg")
    page.get_by_role("button", name=f"Open scan {empty + 1} in the result").click()
    expect(page.locator("#result-body")).to_contain_text("no part found")
    expect(page.locator("#overlay-figure")).to_be_hidden()


def test_photos_dropped_on_the_page(page, station_json, folder, tmp_path):
    """Photos dragged onto the drop zone (as a file manager drops them) join the list; one of
    another size than the station's camera is flagged and left out before anything is sent."""
    root, _ = folder
    _station_mode(page)
    if not page.locator("#stations tbody tr").count():
        _store(page, station_json, "line 1")
    small = cv2.resize(cv2.imread(str(root / "part-1.jpg")), (640, 512))
    cv2.imwrite(str(tmp_path / "small.jpg"), small)
    names = ["part-1.jpg", "part-2.jpg"]
    files = [{"name": n, "data": list((root / n).read_bytes())} for n in names]
    files.append({"name": "small.jpg", "data": list((tmp_path / "small.jpg").read_bytes())})
    page.locator("#drop-zone").evaluate("""(zone, files) => {
        const data = new DataTransfer();
        for (const f of files) {
            data.items.add(new File([new Uint8Array(f.data)], f.name, {type: 'image/jpeg'}));
        }
        zone.dispatchEvent(new DragEvent('dragover', {dataTransfer: data, bubbles: true, cancelable: true}));
        zone.dispatchEvent(new DragEvent('drop', {dataTransfer: data, bubbles: true, cancelable: true}));
    }""", files)
    summary = page.locator("#station-photos-summary")
    expect(summary).to_contain_text("3 photos · all uploaded · 1 cannot be measured on this station")
    expect(page.locator("#station-photo-list li")).to_have_text([
        *(f"{n}: uploaded" for n in names),
        f"small.jpg: left out: 640 {TIMES} 512 px, the station's camera takes 1280 {TIMES} 1024 px"])
    expect(page.locator("#station-photo-details")).to_have_attribute("open", "")
    expect(page.get_by_role("button", name=re.compile(r"^Measure 2 photos on "))).to_be_visible()


def test_a_station_calibrated_by_the_service_from_its_photos(page, setup, tmp_path):
    """board.json, the plane photo, the board in 8 poses and the empty support: the service
    calibrates the camera and the plane, and the page lists the station it stored and uses it."""
    plate = station_scene(100, setup).plate
    (tmp_path / "board.json").write_text(json.dumps(setup.board.describe()))
    (tmp_path / "plane.jpg").write_bytes(_jpeg(plate))
    poses = []
    for k, view in enumerate(calibration_views(setup, 8, seed=5)):
        poses.append(tmp_path / f"pose{k}.jpg")
        poses[-1].write_bytes(_jpeg(view))
    _station_mode(page)
    if page.locator("#new-station").get_attribute("open") is None:
        page.get_by_text("Add a station").click()
    page.get_by_label("Name (optional)").fill("calibrated here")
    page.get_by_label("Board (board.json)").set_input_files(str(tmp_path / "board.json"))
    page.get_by_label("Plane photo").set_input_files(str(tmp_path / "plane.jpg"))
    page.get_by_label("Calibration photos: the board").set_input_files([str(p) for p in poses])
    page.get_by_label("Empty support").set_input_files(str(tmp_path / "plane.jpg"))
    page.get_by_role("button", name="Calibrate and store").click()
    expect(page.locator("#station-status")).to_contain_text("Stored calibrated here", timeout=120_000)
    row = page.locator("#stations tbody tr.current")
    expect(row).to_contain_text("calibrated here")
    # the 8 poses and the plane photo: the board's views the intrinsics were fitted to
    expect(row).to_contain_text(re.compile(r"calibrated on 9 views of the board, RMS 0\.\d\d px"))
    expect(row).to_contain_text("stored")
    expect(page.locator("#station-error")).to_be_empty()


def test_a_calibration_refused_in_words_and_a_station_deleted(page, setup, station_json, tmp_path):
    _station_mode(page)
    if page.locator("#new-station").get_attribute("open") is None:
        page.get_by_text("Add a station").click()
    bad = tmp_path / "board.json"
    bad.write_text(json.dumps({**setup.board.describe(), "square_mm": -1}))
    plain = tmp_path / "grey.jpg"
    plain.write_bytes(_jpeg(np.full((SIZE[1], SIZE[0], 3), 128, np.uint8)))
    page.get_by_label("Board (board.json)").set_input_files(str(bad))
    page.get_by_label("Plane photo").set_input_files(str(plain))
    pose = tmp_path / "pose.jpg"
    pose.write_bytes(_jpeg(calibration_views(setup, 1, seed=5)[0]))
    page.get_by_label("Calibration photos: the board").set_input_files(str(pose))
    page.get_by_role("button", name="Calibrate and store").click()
    error = page.locator("#station-error")
    expect(error).to_contain_text("The station was refused. Board (board.json), square_mm: ")
    # A good board, but a plane photo without it: the plane photo named, and why.
    good = tmp_path / "good-board.json"
    good.write_text(json.dumps(setup.board.describe()))
    page.get_by_label("Board (board.json)").set_input_files(str(good))
    page.get_by_role("button", name="Calibrate and store").click()
    expect(error).to_contain_text("Plane photo (grey.jpg): 0 board corners found")  # the file named once
    expect(page.locator("#station-status")).to_contain_text("Not stored.")
    _shot(page, "station-refused.png")

    # Delete one from its row (after the confirmation).
    _store(page, station_json, "to delete")
    row = page.locator("#stations tbody tr", has_text="to delete")
    expect(row).to_have_count(1)
    page.once("dialog", lambda dialog: dialog.accept())
    page.get_by_role("button", name=re.compile(r"^Delete to delete")).click()
    expect(page.locator("#station-status")).to_contain_text("Deleted to delete")
    expect(row).to_have_count(0)


def test_a_large_batch_is_polled_without_its_items(page, station_json, folder):
    """A station's folder of 60 photos: while the job runs the page asks for its state and
    progress only (item_limit=0), and reads the items once, when it has ended. The job's answers
    are the service's shapes, played back (60 renders measured would cost CI minutes)."""
    root, _ = folder
    _station_mode(page)
    if not page.locator("#stations tbody tr").count():
        _store(page, station_json, "line 1")
    job_id = "f" * 32
    n = 60

    def job(state: str, progress: int, items: bool) -> dict:
        done = n if state == "failed" else n // 2
        return {"id": job_id, "state": state, "progress": progress, "items_done": done,
                "items_failed": done, "item_count": n,
                "created_at": "2026-01-01T00:00:00Z", "started_at": "2026-01-01T00:00:01Z",
                "finished_at": None, "client_reference": "station",
                "error": "all items failed" if state == "failed" else None,
                "items": [{"index": i, "state": "failed", "error": "no part found on the support",
                           "result": None, "downloads": {}, "frames": []} for i in range(n)] if items else []}

    asked: list[str] = []
    polls = iter([job("running", 50, False), job("failed", 100, False)])

    def answer(route) -> None:
        url = route.request.url
        asked.append(url)
        if route.request.method == "POST":
            body = job("queued", 0, True)
        elif url.endswith("/results.json"):
            body = {"job_id": job_id, "client_reference": "station", "state": "failed",
                    "verdicts": {"pass": 0, "fail": 0, "uncertain": 0}, "columns": [],
                    "rows": [{"item": i, "frame": None, "input": f"upload:{i}", "state": "failed",
                              "error": "no part found on the support", "verdict": None} for i in range(n)]}
        elif "item_limit=0" in url:
            body = next(polls)
        else:
            body = job("failed", 100, True)
        route.fulfill(status=202 if route.request.method == "POST" else 200, json=body)

    page.route(re.compile(r"/v1/jobs(/f{32}(\?item_limit=0|/results\.json)?)?$"), answer)
    page.locator("#station-files").set_input_files(str(root / "part-1.jpg"))
    expect(page.locator("#station-photos-summary")).to_contain_text("1 photo · all uploaded")
    page.get_by_role("button", name=re.compile(r"^Measure 1 photo on ")).click()
    expect(page.locator("#job-state")).to_contain_text(f"Failed. {n} of {n} scans failed.")
    expect(page.locator("#job-state")).not_to_contain_text("items")
    expect(page.locator("#table-count")).to_contain_text(f"{n} of {n} rows shown")
    polled = [u for u in asked if f"/v1/jobs/{job_id}" in u and not u.endswith("results.json")]
    assert [u.endswith("?item_limit=0") for u in polled] == [True, True, False], asked

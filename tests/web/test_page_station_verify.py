"""A station verified from the page, against the real stack: the station's row states "not
verified" and its capability (mm per px over the support, the smallest part and tolerance), the
reference part's photos, its size and tolerance sent from "Verify the chosen station" (POST
/v1/stations/{id}/verifications), the figures shown in a table and the verdict in words, the row
then "verified on DATE"; a refusal said at the field at fault; and a part measured on the verified
station, its row of the job's table stating "verified on DATE" and the camera's shift (a part
measured before the verification: "not verified", marked, warned). Screenshots go to
test-artifacts/web/.

The photos are the example station's (`prism sample --station`'s camera, board and reference
placements), the station calibrated with its true camera.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from page_driver import PageDriver
from playwright.sync_api import expect

from prism_cli.sample_command import reference_placements
from prismcore.camera import CameraModel
from prismcore.station import calibrate_station
from prismcore.station.board import default_board
from prismsynth.station import StationSetup, station_scene, station_setup

ARTEFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "web"
SAMPLE_SEED = 11  # prism sample --station's setup
TIMES, DASH = "\N{MULTIPLICATION SIGN}", "\N{EN DASH}"


def _jpeg(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    return data.tobytes()


@pytest.fixture(scope="module")
def setup() -> StationSetup:
    return station_setup(SAMPLE_SEED, board=default_board())


@pytest.fixture(scope="module")
def files(setup, tmp_path_factory) -> dict[str, Path | list[Path]]:
    """station.json, the reference's 7 photos and one part's photo."""
    root = tmp_path_factory.mktemp("verify")
    plate = station_scene(SAMPLE_SEED, setup, parts=0).plate
    w, h = setup.image_size
    camera = CameraModel(fx=setup.K[0, 0], fy=setup.K[1, 1], cx=setup.K[0, 2], cy=setup.K[1, 2],
                         dist=[float(v) for v in setup.dist], image_width=w, image_height=h)
    (root / "station.json").write_text(
        calibrate_station(setup.board, plate, camera=camera, plate=plate).model_dump_json())
    photos = []
    for i, box in enumerate(reference_placements(setup), 1):
        photos.append(root / f"reference-{i}.jpg")
        photos[-1].write_bytes(_jpeg(station_scene(100 + i, setup, box=box).photo))
    (root / "part.jpg").write_bytes(_jpeg(station_scene(23, setup, max_size_mm=150).photo))
    return {"station": root / "station.json", "photos": photos, "part": root / "part.jpg"}


def test_a_station_verified_from_the_page_and_its_parts_state_it(page, files):
    d = PageDriver(page)
    d.log_in()
    page.get_by_label("Station", exact=True).check()
    expect(page.locator("#station-status")).to_contain_text("station")
    if page.locator("#new-station").get_attribute("open") is None:
        page.get_by_text("Add a station").click()
    page.get_by_label("Name (optional)").fill("line 9")
    page.get_by_label("station.json").set_input_files(str(files["station"]))
    page.get_by_role("button", name="Store the station").click()
    expect(page.locator("#station-status")).to_contain_text("Stored line 9")
    row = page.locator("#stations tbody tr", has_text="line 9").first
    expect(row.locator("td[data-col=verification]")).to_have_text("not verified")
    expect(row.locator("td[data-col=verification]")).to_have_class(re.compile(r"\berror\b"))
    expect(row.locator("td[data-col=capability]")).to_contain_text(
        re.compile(rf"0\.\d\d{DASH}0\.\d\d mm/px; parts ≥ \d+ mm"))

    # A part measured before the station is verified: its row says "not verified", marked, and the
    # scan's warning says why.
    page.locator("#station-files").set_input_files(str(files["part"]))
    expect(page.locator("#station-photos-summary")).to_contain_text("1 photo")
    page.get_by_role("button", name=re.compile(r"Measure 1 photo on line 9")).click()
    expect(page.locator("#job-state")).to_contain_text("Done", timeout=300_000)
    cell = page.locator("#results-table tbody tr td[data-col=station]").first
    expect(cell).to_have_text(re.compile(r"^not verified · camera moved \d+\.\d px \(\d+\.\d mm\)$"))
    expect(cell).to_have_class(re.compile(r"\bwarned\b"))
    expect(page.locator("#results-table tbody tr td[data-col=warnings]").first).to_contain_text(
        "the station is not verified: its measurements are not checked against a part of known size")

    page.get_by_text("Verify the chosen station with a reference part").click()
    page.get_by_label("Its true size W,D,H in mm").fill("70x45x30")
    page.get_by_label("Tolerance ± T in mm").fill("2")
    photos = [str(p) for p in files["photos"]]  # type: ignore[union-attr]
    page.get_by_label("Its photos, one per placement").set_input_files(photos[:5])
    page.get_by_role("button", name="Verify", exact=True).click()
    expect(page.locator("#verify-error")).to_contain_text(
        "The verification was refused. Reference size: reference '70x45x30': expected W,D,H in mm")
    page.get_by_label("Its photos, one per placement").set_input_files(photos[:3])
    page.get_by_role("button", name="Verify", exact=True).click()
    expect(page.locator("#verify-error")).to_have_text(
        "Choose the reference part's photos, one per placement: 5 at least (3 chosen).")

    page.get_by_label("Its true size W,D,H in mm").fill("70,45,30")
    page.get_by_label("Its photos, one per placement").set_input_files(photos)
    posted = lambda r: r.url.endswith("/verifications") and r.request.method == "POST"  # noqa: E731
    with page.expect_response(posted) as got:
        page.get_by_role("button", name="Verify", exact=True).click()
    assert got.value.status == 201
    expect(page.locator("#verify-verdict")).to_contain_text(
        "Verified on 20", timeout=120_000)
    expect(page.locator("#verify-verdict")).to_contain_text(
        f"with a 70 {TIMES} 45 {TIMES} 30 mm reference (width {TIMES} depth {TIMES} height), 7 placements, "
        "tolerance ± 2 mm.")
    table = page.locator("#verify-table tbody tr")
    expect(table).to_have_count(3)
    for name in ("width", "depth", "height"):
        cells = page.locator(f"#verify-table tr[data-dimension={name}] td")
        expect(cells.nth(5)).to_have_text("7 of 7")
        expect(cells.nth(7)).to_have_text("ok")
    expect(page.locator("#station-status")).to_contain_text("Verified: line 9.")
    row = page.locator("#stations tbody tr", has_text="line 9").first
    verified = row.locator("td[data-col=verification]")
    expect(verified).to_have_text(re.compile(r"^verified on \d{4}-\d\d-\d\d$"))
    assert "bias" in (verified.get_attribute("title") or "")
    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTEFACTS / "station-verified.png"), full_page=True)

    # A part measured on it: its row says the station was verified, and how far the camera moved.
    page.locator("#station-files").set_input_files(str(files["part"]))
    expect(page.locator("#station-photos-summary")).to_contain_text("1 photo")
    page.get_by_role("button", name=re.compile(r"Measure 1 photo on line 9")).click()
    expect(page.locator("#job-state")).to_contain_text("Done", timeout=300_000)
    cell = page.locator("#results-table tbody tr td[data-col=station]").first
    verified_row = r"^verified on \d{4}-\d\d-\d\d · camera moved \d+\.\d px \(\d+\.\d mm\)$"
    expect(cell).to_have_text(re.compile(verified_row))
    expect(cell).not_to_have_class(re.compile(r"\bwarned\b"))
    expect(page.locator("#results-table tbody tr td[data-col=warnings]").first).not_to_contain_text(
        "not verified")
    stored = json.loads(files["station"].read_text())  # type: ignore[union-attr]
    assert stored.get("verification") is None  # the service stored it, not the file

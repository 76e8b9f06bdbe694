"""The results table's logic (`prism_api.results_table`) over the job store on fakeredis: rows of
items and video frames, CSV and JSON telling the same table, a 10,000-item job read in pages
(never whole), and the verdict counts the store keeps with each item's completion."""

from __future__ import annotations

import csv
import io
import json
import uuid
from datetime import UTC, datetime

import fakeredis
import numpy as np
import pytest
from prism_common.records import FrameRecord, ItemRecord, ItemResult, JobRecord, State
from prism_common.store import JobStore

from prism_api.results_table import COLUMNS, PAGE_ITEMS, csv_chunks, json_chunks, pages
from prismcore.spec import ScanSpec
from prismcore.station.certify import verification_status
from prismcore.station.verify import Verification, verify_placements

POINTS = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]
PHOTO = ScanSpec.model_validate({"image": "upload:" + "a" * 32, "points": POINTS})
VIDEO = ScanSpec.model_validate({"image": "upload:" + "b" * 32, "points": POINTS,
                                 "frames": {"indices": [3, 7]}})
STATION = ScanSpec.model_validate({"image": "upload:" + "c" * 32, "station": "d" * 32})


def _quality(verdict: str, deviations: tuple[float, float, float]) -> dict:
    return {"verdict": verdict, "k": 2.0, "counts": {},
            "dimensions": {d: {"verdict": verdict, "deviation_mm": dev}
                           for d, dev in zip(("width", "height", "depth"), deviations, strict=True)}}


def _result(width: float, verdict: str | None = None) -> ItemResult:
    return ItemResult(points=1234, dimensions={"width": width, "height": 80.0, "depth": 60.0, "unit": "mm"},
                      point_loss=0.01, uncertainty={"width": 0.2, "height": 0.3, "depth": 0.4},
                      quality=_quality(verdict, (0.5, -0.25, 0.0)) if verdict else None,
                      points_source="clicked",
                      reference_points={"p1": [10.5, 10.25], "p2": [110.0, 12.0], "p6": None})


@pytest.fixture
def store() -> JobStore:
    return JobStore(fakeredis.FakeRedis(decode_responses=True))


def _make(store: JobStore, items: list[ItemRecord]) -> JobRecord:
    job, _ = store.create(JobRecord(id=uuid.uuid4().hex, tenant="acme", items=items,
                                    created_at=datetime.now(UTC), client_reference="batch 7"))
    return job


def _table(store: JobStore, job_id: str, page_items: int = PAGE_ITEMS) -> tuple[str, dict, list[int]]:
    """(CSV text, parsed JSON, the limit of every page read) of the job's table."""
    reads: list[int] = []

    def read(offset: int, limit: int) -> JobRecord | None:
        reads.append(limit)
        found = store.get_page(job_id, offset, limit)
        return found[0] if found else None

    def all_pages():
        first, n = store.get_page(job_id, 0, page_items)
        reads.append(page_items)
        return pages(first, n, read, page_items)

    text = "".join(csv_chunks(all_pages()))
    doc = json.loads("".join(json_chunks({"job_id": job_id}, all_pages())))
    return text, doc, reads


def test_rows_of_items_and_frames_agree_in_csv_and_json(store):
    job = _make(store, [ItemRecord(index=0, spec=PHOTO), ItemRecord(index=1, spec=PHOTO),
                        ItemRecord(index=2, spec=VIDEO)])
    store.put_item(job.id, ItemRecord(index=0, spec=PHOTO, state=State.succeeded,
                                      result=_result(100.5, "fail")))
    store.put_item(job.id, ItemRecord(index=1, spec=PHOTO, state=State.failed, error="no box, no fit"))
    store.put_item(job.id, ItemRecord(index=2, spec=VIDEO, state=State.succeeded, result=_result(99.0)))
    store.put_frame(job.id, 2, FrameRecord(index=7, state=State.succeeded, result=_result(99.25, "pass")))
    store.put_frame(job.id, 2, FrameRecord(index=3, state=State.failed, error="blurred"))
    text, doc, _ = _table(store, job.id)

    rows = list(csv.DictReader(io.StringIO(text)))
    assert tuple(rows[0]) == COLUMNS == tuple(doc["columns"])
    assert [(r["item"], r["frame"], r["state"]) for r in rows] == [
        ("0", "", "succeeded"), ("1", "", "failed"), ("2", "", "succeeded"),
        ("2", "3", "failed"), ("2", "7", "succeeded")]
    first = rows[0]
    assert (first["job_id"], first["client_reference"], first["input"]) == (job.id, "batch 7", PHOTO.image)
    assert (first["width"], first["width_sigma"], first["unit"], first["cloud_points"]) == (
        "100.5", "0.2", "mm", "1234")
    assert (first["verdict"], first["height_verdict"], first["height_deviation_mm"]) == (
        "fail", "fail", "-0.25")
    assert (first["p1_x"], first["p1_y"], first["p6_x"], first["points_source"]) == (
        "10.5", "10.25", "", "clicked")
    failed = rows[1]  # no result: the spec's own points, no figures
    assert (failed["error"], failed["width"], failed["verdict"]) == ("no box, no fit", "", "")
    assert (failed["p2_x"], failed["p5_y"], failed["p6_x"]) == ("110.0", "8.0", "")
    assert rows[3]["error"] == "blurred" and rows[4]["verdict"] == "pass" and rows[2]["verdict"] == ""
    # The JSON is the same table, typed.
    assert len(doc["rows"]) == len(rows)
    for as_csv, as_json in zip(rows, doc["rows"], strict=True):
        assert as_csv == {k: "" if v is None else str(v) for k, v in as_json.items()}
    assert doc["rows"][0]["width"] == 100.5 and doc["rows"][1]["width"] is None


@pytest.mark.parametrize(("spec", "source"), [(PHOTO, "clicked"), (STATION, "station")])
def test_a_failed_item_s_points_source_is_its_kind_s(store, spec, source):
    """A failed item has no result to say where its points came from: a station's row says
    station (it read "clicked" for a station photo that failed), a clicked photo's clicked."""
    job = _make(store, [ItemRecord(index=0, spec=spec)])
    store.put_item(job.id, ItemRecord(index=0, spec=spec, state=State.failed, error="no part found"))
    text, doc, _ = _table(store, job.id)
    [row] = list(csv.DictReader(io.StringIO(text)))
    assert row["points_source"] == doc["rows"][0]["points_source"] == source


def test_a_10000_item_job_is_read_a_page_at_a_time(store):
    n = 10_000
    job = _make(store, [ItemRecord(index=i, spec=PHOTO) for i in range(n)])
    for i in range(0, n, 997):  # a few finished ones spread over the pages
        store.put_item(job.id, ItemRecord(index=i, spec=PHOTO, state=State.succeeded,
                                          result=_result(float(i))))
    text, doc, reads = _table(store, job.id)
    rows = list(csv.DictReader(io.StringIO(text)))
    assert [int(r["item"]) for r in rows] == list(range(n)) == [r["item"] for r in doc["rows"]]
    assert {int(r["item"]) for r in rows if r["state"] == "succeeded"} == set(range(0, n, 997))
    assert all(float(r["width"]) == int(r["item"]) for r in rows if r["state"] == "succeeded")
    # Never more than a page of items from the store at once: both tables, 50 pages each.
    assert max(reads) == PAGE_ITEMS and len(reads) == 2 * n // PAGE_ITEMS


def test_a_job_deleted_while_streamed_ends_its_table(store):
    job = _make(store, [ItemRecord(index=i, spec=PHOTO) for i in range(5)])
    first, n = store.get_page(job.id, 0, 2)
    assert [len(p.items) for p in pages(first, n, lambda o, lim: None, 2)] == [2]


def test_verdicts_are_counted_once_per_item_with_its_completion(store):
    job = _make(store, [ItemRecord(index=i, spec=PHOTO) for i in range(4)])
    for i, verdict in enumerate(("pass", "fail", "pass", None)):
        for _ in range(2):  # a redelivered completion counts nothing twice
            store.item_done(job.id, i, verdict)
    assert store.get(job.id).verdicts == {"pass": 2, "fail": 1, "uncertain": 0}
    assert store.get_page(job.id, 0, 0)[0].verdicts == {"pass": 2, "fail": 1, "uncertain": 0}


@pytest.mark.parametrize("reference", ["=1+2", "+1+2", "-1+2", "@SUM(A1:A2)", "\t=1+2", "\r=1+2",
                                       "=HYPERLINK(\"http://x.example\",\"y\")"])
def test_a_text_cell_a_spreadsheet_would_run_is_written_as_text(store, reference):
    """OWASP's CSV injection: a cell starting with =, +, -, @, a tab or a CR gets a leading single
    quote in the CSV (a spreadsheet shows it as text); the JSON keeps the value as given, and
    numbers (a negative deviation too) stay numbers."""
    job, _ = store.create(JobRecord(id=uuid.uuid4().hex, tenant="acme", created_at=datetime.now(UTC),
                                    client_reference=reference,
                                    items=[ItemRecord(index=0, spec=PHOTO), ItemRecord(index=1, spec=PHOTO)]))
    store.put_item(job.id, ItemRecord(index=0, spec=PHOTO, state=State.succeeded,
                                      result=_result(100.5, "fail")))
    store.put_item(job.id, ItemRecord(index=1, spec=PHOTO, state=State.failed, error=reference))
    text, doc, _ = _table(store, job.id)
    rows = list(csv.DictReader(io.StringIO(text)))
    assert [r["client_reference"] for r in rows] == ["'" + reference] * 2
    assert rows[1]["error"] == "'" + reference
    assert rows[0]["height_deviation_mm"] == "-0.25"  # a number, not text: left as it is
    assert [r["client_reference"] for r in doc["rows"]] == [reference] * 2
    assert doc["rows"][1]["error"] == reference and doc["rows"][0]["height_deviation_mm"] == -0.25


def _verification(reference_width: float) -> Verification:
    """A verification of a 70 x 45 x 30 mm reference over 6 placements, made on 2026-03-04 (a
    `reference_width` other than 70 fails it)."""
    rng = np.random.default_rng(5)
    measured = np.array([70.0, 45.0, 30.0]) + rng.normal(0.0, 0.05, (6, 3))
    return verify_placements(measured, np.full((6, 3), 0.3), (reference_width, 45.0, 30.0), 2.0,
                             positions_mm=[(20, 20), (180, 20), (100, 75), (20, 130), (180, 130), (100, 20)],
                             yaws_deg=[0, 30, 60, 90, 120, 150], board_size_mm=(210, 150),
                             photos=[str(i) for i in range(6)],
                             date=datetime(2026, 3, 4, 5, 6, tzinfo=UTC))


def _on_station(status: dict, shift_px: float, reverify: bool) -> ItemResult:
    drift = {"shift_px": shift_px, "shift_mm": round(shift_px * 0.3, 2), "moved": shift_px > 4,
             "reverify": reverify, "cost_mm": {}, "allowed_mm": {}, "threshold_px": None,
             "tolerance_from": "the measurement's tolerance", "moved_over_px": 4.0}
    return _result(70.1).model_copy(update={"points_source": "station",
                                            "station": {"verification": status, "drift": drift}})


def test_a_station_row_states_its_verification_its_date_and_the_cameras_move(store):
    """Each station item's row: its verification's status as the engine words it (verified, not
    verified, verified before the camera moved), the verification's day, the camera's shift and
    whether that move asks for re-verification; a clicked photo's row leaves them empty."""
    statuses = [
        verification_status(_verification(70.0), moved=False),
        verification_status(None, moved=False),
        verification_status(_verification(72.0), moved=False),
        verification_status(_verification(70.0), moved=True, shift_px=10.0, shift_mm=3.0),
    ]
    results = [_on_station(statuses[0], 1.5, False), _on_station(statuses[1], 0.5, False),
               _on_station(statuses[2], 0.5, False), _on_station(statuses[3], 10.0, True)]
    job = _make(store, [*(ItemRecord(index=i, spec=STATION) for i in range(4)),
                        ItemRecord(index=4, spec=PHOTO)])
    for i, result in enumerate(results):
        store.put_item(job.id, ItemRecord(index=i, spec=STATION, state=State.succeeded, result=result))
    store.put_item(job.id, ItemRecord(index=4, spec=PHOTO, state=State.succeeded, result=_result(100.0)))
    text, doc, _ = _table(store, job.id)
    rows = list(csv.DictReader(io.StringIO(text)))
    columns = ("station_verification", "station_verification_date", "camera_shift_px", "camera_shift_mm",
               "station_reverify")
    assert [tuple(r[c] for c in columns) for r in rows] == [
        ("verified", "2026-03-04", "1.5", "0.45", "False"),
        ("not verified", "", "0.5", "0.15", "False"),
        ("not verified", "2026-03-04", "0.5", "0.15", "False"),  # its verification failed
        ("verified before the camera moved", "2026-03-04", "10.0", "3.0", "True"),
        ("", "", "", "", ""),
    ]
    assert [r["station_verification_date"] for r in doc["rows"]] == [
        "2026-03-04", None, "2026-03-04", "2026-03-04", None]
    assert [r["station_reverify"] for r in doc["rows"]] == [False, False, False, True, None]


def test_a_row_names_the_file_sent_the_item_s_reference_its_warnings_and_tracked_points(store):
    """Issue 38: the upload's file name and the item's reference recorded at submit, the result's
    warnings in one cell, and a tracked video's frames say tracked (but the frame marked: clicked)."""
    tracked = ScanSpec.model_validate({"image": "upload:" + "e" * 32, "points_frame": 3,
                                       "points": [*POINTS, [12, 70], [190, 60]],
                                       "frames": {"indices": [3, 7]}})
    assert tracked.kind == "tracked"
    warned = _result(100.0).model_copy(update={"warnings": ["blurred edge", "no scale"]})
    named = PHOTO.model_copy(update={"reference": "part 7"})
    job = _make(store, [ItemRecord(index=0, spec=named, file_name="box 7.jpg"),
                        ItemRecord(index=1, spec=tracked)])
    store.put_item(job.id, ItemRecord(index=0, spec=named, file_name="box 7.jpg",
                                      state=State.succeeded, result=warned))
    for frame in (3, 7):
        store.put_frame(job.id, 1, FrameRecord(index=frame, state=State.succeeded, result=_result(99.0)))
    text, doc, _ = _table(store, job.id)
    rows = list(csv.DictReader(io.StringIO(text)))
    assert (rows[0]["file_name"], rows[0]["item_reference"], rows[0]["warnings"]) == (
        "box 7.jpg", "part 7", "blurred edge | no scale")
    assert [(r["frame"], r["points_source"]) for r in rows[1:]] == [
        ("", "tracked"), ("3", "clicked"), ("7", "tracked")]
    assert doc["rows"][1]["file_name"] is None and doc["rows"][1]["warnings"] is None

"""The typed API client's logic against scripted answers (httpx.MockTransport): retries that
honour Retry-After, one Idempotency-Key across a submit's retries, problem details in one line,
one upload per file. The real-stack tier (tests/test_docs.py, test_stack.py) runs it for real."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from prism_common.public import JobPublic

from prism_cli.client import ApiClient, ApiError, format_eta, remaining_s

NOW = datetime(2026, 12, 1, 12, 0, tzinfo=UTC)


def job_doc(**over) -> dict:
    doc = {"id": "j1", "state": "running", "progress": 40, "items_done": 2, "created_at": NOW.isoformat(),
           "started_at": (NOW - timedelta(seconds=20)).isoformat(), "finished_at": None,
           "client_reference": None, "webhook_url": None, "error": None, "item_count": 5, "items": []}
    return doc | over


def client_for(handler, sleeps: list[float] | None = None, retries: int = 5) -> ApiClient:
    return ApiClient("http://api.test", "k-test", transport=httpx.MockTransport(handler),
                     retries=retries, sleep=(sleeps.append if sleeps is not None else lambda s: None))


@pytest.mark.parametrize(("status", "retry_after", "expected"), [(429, "7", 7.0), (503, "0", 0.0),
                                                                 (503, None, 1.0)])
def test_429_and_503_are_retried_after_retry_after(status, retry_after, expected):
    calls: list[httpx.Request] = []

    def handler(request: httpx.Request) -> httpx.Response:
        calls.append(request)
        if len(calls) == 1:
            headers = {"Retry-After": retry_after} if retry_after is not None else {}
            return httpx.Response(status, headers=headers, json={"detail": "busy"})
        return httpx.Response(202, json=job_doc())

    sleeps: list[float] = []
    job = client_for(handler, sleeps).submit({"items": []})
    assert isinstance(job, JobPublic) and job.id == "j1"
    assert sleeps == [expected]
    # Both attempts carried the same Idempotency-Key: the retry cannot make a second job.
    keys = {r.headers["Idempotency-Key"] for r in calls}
    assert len(calls) == 2 and len(keys) == 1


def test_retries_run_out_with_the_last_answer():
    def handler(request):
        return httpx.Response(503, headers={"Retry-After": "1"},
                              json={"type": "x", "title": "Unavailable", "status": 503,
                                    "detail": "at capacity"})

    sleeps: list[float] = []
    with pytest.raises(ApiError) as err:
        client_for(handler, sleeps, retries=3).job("j1")
    assert sleeps == [1.0, 1.0, 1.0]
    assert str(err.value) == "HTTP 503: at capacity" and err.value.status == 503


def test_a_given_idempotency_key_is_sent_as_is():
    seen = []

    def handler(request):
        seen.append(request.headers["Idempotency-Key"])
        return httpx.Response(202, json=job_doc())

    client_for(handler).submit({"items": []}, idempotency_key="order-42")
    assert seen == ["order-42"]


def test_a_problem_prints_as_one_line_with_its_pointers():
    problem = {"type": "https://prismcloud.dev/problems/validation", "title": "Invalid request",
               "status": 422, "detail": "The request body is not a valid job.\nSee errors.",
               "errors": [{"pointer": "/items/0/points/p5", "detail": "outside the photo"}]}

    with pytest.raises(ApiError) as err:
        client_for(lambda r: httpx.Response(422, json=problem)).job("j1")
    message = str(err.value)
    assert "\n" not in message
    assert message == ("HTTP 422: The request body is not a valid job. See errors. "
                       "(/items/0/points/p5: outside the photo)")
    assert err.value.problem["errors"][0]["pointer"] == "/items/0/points/p5"


def test_a_non_json_error_is_one_line():
    with pytest.raises(ApiError, match=r"^HTTP 502: bad gateway upstream$"):
        client_for(lambda r: httpx.Response(502, text="bad gateway\n  upstream\n")).job("j1")


def test_each_file_is_uploaded_once(tmp_path: Path):
    photo = tmp_path / "box.jpg"
    photo.write_bytes(b"\xff\xd8\xff" + b"0" * 100)
    count = 0

    def handler(request):
        nonlocal count
        count += 1
        return httpx.Response(201, json={"id": f"u{count}", "reference": f"upload:u{count}"})

    client = client_for(handler)
    assert {client.upload(photo) for _ in range(3)} == {"upload:u1"}
    photo.write_bytes(b"\xff\xd8\xff" + b"1" * 200)  # changed on disk: sent again
    assert client.upload(photo) == "upload:u2" and count == 2


def test_jobs_pages_through_the_cursor():
    pages = {None: ({"jobs": [job_doc(id="a"), job_doc(id="b")], "next_cursor": "c1"}),
             "c1": ({"jobs": [job_doc(id="c")], "next_cursor": None})}

    def handler(request):
        assert request.url.params["items"] == "false"
        return httpx.Response(200, json=pages[request.url.params.get("cursor")])

    assert [j.id for j in client_for(handler).iter_jobs(page=2)] == ["a", "b", "c"]


def test_wait_polls_without_items_then_reads_the_job_whole():
    answers = iter([job_doc(progress=10), job_doc(progress=60), job_doc(state="succeeded", progress=100),
                    job_doc(state="succeeded", progress=100, items_done=5)])
    asked = []

    def handler(request):
        asked.append(request.url.params.get("item_limit"))
        return httpx.Response(200, json=next(answers))

    seen = []
    job = client_for(handler).wait("j1", timeout=10, on_update=lambda j: seen.append(j.progress))
    assert seen == [10, 60, 100] and job.items_done == 5
    assert asked == ["0", "0", "0", None]


def test_remaining_time_is_estimated_from_the_progress_rate():
    job = JobPublic.model_validate(job_doc(progress=40))  # 40 % in 20 s: 30 s to go
    assert remaining_s(job, NOW) == pytest.approx(30.0)
    assert remaining_s(JobPublic.model_validate(job_doc(progress=0)), NOW) is None
    assert remaining_s(JobPublic.model_validate(job_doc(state="succeeded", progress=100)), NOW) is None
    assert format_eta(30.0) == "about 30 s left" and format_eta(600) == "about 10 min left"
    assert format_eta(None) == ""


def test_body_is_sent_as_json():
    def handler(request):
        assert json.loads(request.content) == {"items": [{"image": "upload:x"}]}
        return httpx.Response(202, json=job_doc())

    client_for(handler).submit({"items": [{"image": "upload:x"}]})


def test_a_station_calibration_at_capacity_is_sent_again_whole(tmp_path):
    """The photos go as (field, file) pairs (calibration given many times): a 503 with
    Retry-After is waited out and the same form sent again (the client once crashed rewinding a
    list of files)."""
    for name in ("board.json", "plane.jpg", "pose0.jpg", "pose1.jpg"):
        (tmp_path / name).write_bytes(name.encode() * 50)
    bodies: list[bytes] = []
    summary = {"id": "s1", "created_at": NOW.isoformat(), "image_width": 640, "image_height": 480,
               "board": {}, "camera": {}, "calibration": {"source": "photos"}, "plane_rms_px": 0.2,
               "plane_corners": 24, "camera_height_mm": 800.0, "has_plate": False, "size": 10}

    def handler(request: httpx.Request) -> httpx.Response:
        bodies.append(request.read())
        if len(bodies) == 1:
            return httpx.Response(503, headers={"Retry-After": "5"}, json={"detail": "2 stations are being "
                                                                                     "calibrated"})
        return httpx.Response(201, json=summary)

    sleeps: list[float] = []
    made = client_for(handler, sleeps).calibrate_station(
        tmp_path / "board.json", tmp_path / "plane.jpg", [tmp_path / "pose0.jpg", tmp_path / "pose1.jpg"])
    assert made.id == "s1" and sleeps == [5.0] and len(bodies) == 2
    assert all(body.count(b'name="calibration"') == 2 and b"pose1.jpg" * 50 in body for body in bodies)

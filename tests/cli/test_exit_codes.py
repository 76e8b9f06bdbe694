"""The `prism` service commands' exit codes and what they print, on a scripted API
(httpx.MockTransport behind the CLI's own client): 0 the command succeeded, 1 the job it waited
for failed or was cancelled (or the wait ran out), 2 bad input or a refused request (4xx), 3 the
API unreachable or failing (5xx, or busy past the retries), with one line on stderr and never a
traceback. The real stack runs them in tests/service/test_cli_stack.py.
"""

from __future__ import annotations

import http.server
import json
import socket
import threading
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
import pytest

from prism_cli import client_commands
from prism_cli.client import ApiClient
from prism_cli.main import main

NOW = datetime(2026, 12, 1, 12, 0, tzinfo=UTC).isoformat()
POINTS = "395,293 943,331 919,761 943,331 1035,298 411,647 1009,660"
KEY = ["--key", "k-test"]


def job_doc(state: str = "succeeded", **over: Any) -> dict[str, Any]:
    doc = {"id": "j1", "state": state, "progress": 100 if state != "running" else 40, "items_done": 1,
           "created_at": NOW, "started_at": NOW, "finished_at": None, "client_reference": None,
           "webhook_url": None, "error": None, "item_count": 1, "items": []}
    return doc | over


def item_doc(state: str = "succeeded", **result: Any) -> dict[str, Any]:
    body = {"points": 639_992, "point_loss": 0.001, "warnings": [],
            "dimensions": {"width": 120.0, "height": 79.99, "depth": 59.98, "unit": "mm"},
            "uncertainty": {"width": 0.0, "height": 0.59, "depth": 0.9},
            "focal_px": 1400.2, "focal_source": "fitted"} | result
    return {"index": 0, "state": state, "error": None if state == "succeeded" else "bad photo",
            "result": body if state == "succeeded" else None, "downloads": {}, "frames": []}


class FakeApi:
    """Answers the CLI's calls: uploads, one submit, then the job in `states` one poll at a time
    (the last one for good); `sent` holds the submitted bodies."""

    def __init__(self, states: list[str], items: list[dict[str, Any]] | None = None) -> None:
        self.states, self.items = list(states), items
        self.sent: list[dict[str, Any]] = []
        self.answers: dict[tuple[str, str], Callable[[httpx.Request], httpx.Response]] = {}

    def job(self) -> dict[str, Any]:
        state = self.states.pop(0) if len(self.states) > 1 else self.states[0]
        items = self.items if self.items is not None else [item_doc(
            "succeeded" if state == "succeeded" else "failed")]
        return job_doc(state, items=items if state != "running" else [])

    def __call__(self, request: httpx.Request) -> httpx.Response:
        answer = self.answers.get((request.method, request.url.path))
        if answer is not None:
            return answer(request)
        if request.url.path == "/v1/uploads":
            return httpx.Response(201, json={"id": "u1", "reference": "upload:u1"})
        if request.method == "POST" and request.url.path == "/v1/jobs":
            self.sent.append(json.loads(request.content))
            return httpx.Response(202, json=job_doc("queued", progress=0, items=[]))
        if request.method == "POST" and request.url.path.endswith("/cancel"):
            return httpx.Response(200, json=job_doc("cancelled", items=[item_doc("cancelled")]))
        if request.url.path == "/v1/jobs":
            return httpx.Response(200, json={"jobs": [job_doc()], "next_cursor": None})
        if request.url.path.startswith("/v1/jobs/"):
            return httpx.Response(200, json=self.job())
        return httpx.Response(404, json={"type": "x", "title": "Not found", "status": 404,
                                         "detail": f"no route {request.url.path}"})


@pytest.fixture
def api(monkeypatch) -> Callable[..., FakeApi]:
    def make(states: list[str], items: list[dict[str, Any]] | None = None) -> FakeApi:
        fake = FakeApi(states, items)
        checked = client_commands._client  # its own checks (a key given) still run

        def scripted(url: str, key: str) -> ApiClient:
            checked(url, key).close()
            return ApiClient(url, key, transport=httpx.MockTransport(fake), sleep=lambda s: None)

        monkeypatch.setattr(client_commands, "_client", scripted)
        return fake

    return make


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str) -> bool:
    return err.count("\n") == 1 and err.startswith("prism: error: ") and "Traceback" not in err


@pytest.mark.parametrize(("final", "code"), [("succeeded", 0), ("completed_with_failures", 1), ("failed", 1),
                                             ("cancelled", 1)])
def test_submit_wait_exits_as_the_job_ended(api, capsys, final: str, code: int):
    api(["queued", "running", final])
    got, out, _ = run(capsys, "submit", "samples/box.jpg", "--points", POINTS, "--width-mm", "120",
                      "--wait", *KEY)
    assert got == code, out
    assert f"job j1: {final}" in out


@pytest.mark.parametrize(("final", "code"), [("succeeded", 0), ("completed_with_failures", 1), ("failed", 1),
                                             ("cancelled", 1)])
def test_wait_exits_as_the_job_ended(api, capsys, final: str, code: int):
    api(["running", final])
    assert run(capsys, "wait", "j1", *KEY)[0] == code


def test_a_wait_that_runs_out_exits_1_in_one_line(api, capsys):
    api(["running"])
    code, _, err = run(capsys, "wait", "j1", "--timeout", "0", *KEY)
    assert code == 1 and one_line_error(err) and "still running after 0 s" in err, err


def test_submit_without_wait_status_cancel_and_jobs_exit_0(api, capsys):
    api(["running", "failed"])
    assert run(capsys, "submit", "samples/box.jpg", "--points", POINTS, "--width-mm", "120", *KEY)[:2] \
        == (0, "j1\n")
    assert run(capsys, "status", "j1", *KEY)[0] == 0  # a failed job's status is still told
    code, out, _ = run(capsys, "cancel", "j1", *KEY)
    assert code == 0 and "cancelled" in out
    assert run(capsys, "jobs", *KEY)[0] == 0


@pytest.mark.parametrize("argv", [
    ["status", "j1"],  # no key
    ["status", "j1", "--bogus", *KEY],
    ["jobs", "--state", "done", *KEY],
    ["submit", "samples/box.jpg", *KEY],  # no points
    ["submit", "samples/box.jpg", "--points", POINTS, "--width-mm", "1e300", *KEY],
    ["submit", "--spec", "no/such/job.json", *KEY],
    ["submit", "--spec", "README.md", *KEY],
    ["submit", "--spec", "samples/box.jpg", *KEY],  # not UTF-8
    ["download", "j1", "--out", "/proc/prism-cannot-write", *KEY],
], ids=["no-key", "bad-option", "bad-state", "no-points", "length-out-of-range", "spec-missing",
        "spec-not-json", "spec-binary", "out-unwritable"])
def test_bad_input_exits_2_in_one_line(api, capsys, monkeypatch, argv: list[str]):
    monkeypatch.delenv("PRISM_API_KEY", raising=False)
    api(["succeeded"], items=[{**item_doc(), "downloads": {"csv": "http://files.test/c.csv"}}])
    code, _, err = run(capsys, *argv)
    assert code == 2 and one_line_error(err), err


def test_a_refused_request_exits_2_with_the_problem_in_one_line(api, capsys):
    fake = api(["succeeded"])
    problem = {"type": "https://prismcloud.dev/problems/not-found", "title": "No such resource",
               "status": 404, "detail": "no job 'nope'"}
    fake.answers[("GET", "/v1/jobs/nope")] = lambda r: httpx.Response(404, json=problem)
    code, _, err = run(capsys, "wait", "nope", *KEY)
    assert code == 2 and err == "prism: error: HTTP 404: no job 'nope'\n"


def test_the_summary_prints_each_dimension_with_its_sigma_and_every_warning_after_it(api, capsys):
    warnings = ["front face: no clear edge along the bottom side; the click was used there",
                "oblique photo measured with the square-on model: ... about 81% on the depth"]
    api(["succeeded"], items=[item_doc(warnings=warnings)])
    code, out, _ = run(capsys, "status", "j1", *KEY)
    assert code == 0
    lines = out.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("  item 0: succeeded"))
    assert "120.00 ± 0.00 x 79.99 ± 0.59 x 59.98 ± 0.90 mm" in lines[at], out
    assert "focal 1400 px (fitted)" in lines[at]
    assert lines[at + 1:at + 3] == [f"    warning: {w}" for w in warnings], out


def test_a_result_without_uncertainty_prints_its_sizes_alone(api, capsys):
    api(["succeeded"], items=[item_doc(uncertainty=None, focal_px=None, focal_source=None)])
    out = run(capsys, "status", "j1", *KEY)[1]
    assert "120.00 x 79.99 x 59.98 mm, 639,992 points" in out and "±" not in out


def test_submit_spec_keeps_the_jobs_reference_and_webhook(api, capsys, tmp_path: Path):
    fake = api(["succeeded"])
    (tmp_path / "box.jpg").write_bytes(b"\xff\xd8\xff" + b"0" * 64)
    item = {"image": "box.jpg", "points": [[1, 1]] * 5}
    spec = tmp_path / "job.json"
    spec.write_text(json.dumps({"items": [item, item], "client_reference": "order-7",
                                "webhook_url": "https://hooks.example.com/prism"}))
    assert run(capsys, "submit", "--spec", str(spec), *KEY)[0] == 0
    assert fake.sent[-1] == {"items": [{**item, "image": "upload:u1"}] * 2, "client_reference": "order-7",
                             "webhook_url": "https://hooks.example.com/prism"}
    # Flags name them too, and win over the file's.
    assert run(capsys, "submit", "--spec", str(spec), "--reference", "order-8", *KEY)[0] == 0
    assert fake.sent[-1]["client_reference"] == "order-8"
    assert fake.sent[-1]["webhook_url"] == "https://hooks.example.com/prism"
    # A scan spec alone is the job's one item; nothing else is added.
    spec.write_text(json.dumps(item))
    assert run(capsys, "submit", "--spec", str(spec), "--webhook", "https://h.example.com/x", *KEY)[0] == 0
    assert fake.sent[-1] == {"items": [{**item, "image": "upload:u1"}], "webhook_url": "https://h.example.com/x"}


def test_an_unknown_field_of_a_job_file_reaches_the_api_to_be_refused(api, capsys, tmp_path: Path):
    fake = api(["succeeded"])
    spec = tmp_path / "job.json"
    spec.write_text(json.dumps({"items": [{"image": "upload:u9", "points": [[1, 1]] * 5}],
                                "webhok_url": "x"}))
    fake.answers[("POST", "/v1/jobs")] = lambda r: httpx.Response(422, json={
        "type": "https://prismcloud.dev/problems/validation", "title": "Invalid input", "status": 422,
        "detail": "/webhok_url: Extra inputs are not permitted",
        "errors": [{"pointer": "/webhok_url", "detail": "Extra inputs are not permitted"}]}
        if "webhok_url" in json.loads(r.content) else {})
    code, _, err = run(capsys, "submit", "--spec", str(spec), *KEY)
    assert code == 2 and one_line_error(err) and "/webhok_url" in err, err


def test_sample_and_schema_exit_0_and_2(capsys, tmp_path: Path):
    code, out, _ = run(capsys, "sample", "--out", str(tmp_path))
    assert code == 0 and (tmp_path / "job.json").is_file(), out
    assert run(capsys, "schema")[0] == 0
    for argv in (["sample", "--out", str(tmp_path), "--width-mm", "-1"],  # was a traceback, exit 1
                 ["sample", "--out", str(tmp_path), "--depth-mm", "1e300"],
                 ["schema", "--bogus"]):
        code, _, err = run(capsys, *argv)
        assert code == 2 and one_line_error(err), (argv, err)


def test_a_value_out_of_range_names_the_spec_field_not_pydantics_validators(capsys, tmp_path: Path):
    code, _, err = run(capsys, "scan", "samples/box.jpg", "--points", POINTS, "--width-mm", "120",
                       "--nominal", "120,80,60", "--tolerance-mm", "2e6", "--out", str(tmp_path))
    assert code == 2 and one_line_error(err), err
    assert err.startswith("prism: error: tolerance_mm: 2e+06 mm is out of range"), err


def _closed_port() -> int:
    with socket.socket() as s:  # bound and closed: nothing listens there now
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_api_that_cannot_be_reached_exits_3_in_one_line(capsys):
    url = f"http://127.0.0.1:{_closed_port()}"
    for argv in (["status", "j1"], ["submit", "samples/box.jpg", "--points", POINTS, "--width-mm", "120"]):
        code, _, err = run(capsys, *argv, "--api", url, *KEY)
        assert code == 3 and one_line_error(err) and "cannot reach the API" in err, (argv, err)


@pytest.mark.parametrize(("status", "code"), [(500, 3), (502, 3), (503, 3), (429, 3), (404, 2), (409, 2),
                                              (422, 2)])
def test_a_failing_api_exits_3_and_a_refusing_one_2(api, capsys, status: int, code: int):
    fake = api(["succeeded"])
    problem = {"type": "about:blank", "title": "x", "status": status, "detail": f"answered {status}"}
    fake.answers[("GET", "/v1/jobs/j1")] = lambda r: httpx.Response(status, json=problem)
    got, _, err = run(capsys, "status", "j1", *KEY)
    assert got == code and one_line_error(err) and f"HTTP {status}" in err, err


@pytest.mark.parametrize(("status", "code"), [(403, 2), (404, 2), (500, 3), (503, 3)])
def test_a_download_link_the_store_refuses_exits_by_its_status(api, capsys, tmp_path, status: int,
                                                               code: int):
    class Refusing(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(status)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Refusing)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        link = f"http://127.0.0.1:{server.server_address[1]}/cloud.laz?X-Amz-Signature=x"
        api(["succeeded"], items=[{**item_doc(), "downloads": {"laz": link}}])
        got, _, err = run(capsys, "download", "j1", "--out", str(tmp_path / "out"), *KEY)
    finally:
        server.shutdown()
        server.server_close()
    assert got == code and one_line_error(err) and f"HTTP {status}" in err, err

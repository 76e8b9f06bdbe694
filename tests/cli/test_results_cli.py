"""`prism results`' table and the client's results calls against scripted answers
(httpx.MockTransport); the real stack runs them in tests/service/test_engineer_outputs.py."""

from __future__ import annotations

import io

import httpx
import pytest
from prism_common.public import ResultsTable
from rich.console import Console

from prism_cli.client import ApiClient, ApiError
from prism_cli.results_command import render_results

ROW = {"item": 0, "frame": None, "state": "succeeded", "width": 120.24, "height": 80.12, "depth": 60.06,
       "unit": "mm", "width_sigma": 0.26, "height_sigma": 0.28, "depth_sigma": 0.57, "cloud_points": 639712,
       "point_loss": 0.0013, "points_source": "clicked", "verdict": "fail", "width_verdict": "fail",
       "height_verdict": "pass", "depth_verdict": "uncertain", "error": None}
TABLE = {"job_id": "j1", "client_reference": "lot 42", "state": "succeeded",
         "verdicts": {"pass": 0, "fail": 1, "uncertain": 1}, "columns": list(ROW),
         "rows": [ROW, ROW | {"frame": 7, "verdict": "uncertain", "width_verdict": "uncertain"},
                  {k: None for k in ROW} | {"item": 1, "state": "failed", "error": "no box [here]"}]}


def _client(handler) -> ApiClient:
    return ApiClient("http://api.test", "k-test", transport=httpx.MockTransport(handler), retries=0)


def test_the_table_shows_each_row_with_sigma_verdicts_and_errors():
    out = io.StringIO()
    render_results(ResultsTable.model_validate(TABLE), Console(file=out, width=200))
    lines = out.getvalue().splitlines()
    assert "lot 42" in lines[0] and "1 fail, 1 uncertain" in lines[0]
    body = [line for line in lines[1:] if "succeeded" in line or "failed" in line]
    assert len(body) == 3
    assert "120.24 ± 0.26" in body[0] and "639,712" in body[0] and "0.1%" in body[0] and "FAIL" in body[0]
    assert " 7 " in body[1] and "UNCERTAIN" in body[1]
    assert "no box [here]" in body[2]  # markup in an error is shown as written


def test_results_and_the_csv_come_from_the_job_routes(tmp_path):
    seen: list[str] = []

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request.url.path)
        if request.url.path.endswith("results.json"):
            return httpx.Response(200, json=TABLE)
        return httpx.Response(200, content=b"job_id,item\r\nj1,0\r\n", headers={"content-type": "text/csv"})

    with _client(handler) as api:
        assert api.results("j1").rows[0]["width"] == 120.24
        saved = api.save_results_csv("j1", tmp_path / "out" / "results.csv")
    assert saved.read_bytes() == b"job_id,item\r\nj1,0\r\n"
    assert seen == ["/v1/jobs/j1/results.json", "/v1/jobs/j1/results.csv"]


def test_an_unknown_job_is_one_line(tmp_path):
    def handler(request: httpx.Request) -> httpx.Response:
        return httpx.Response(404, json={"type": "x", "title": "No such resource", "status": 404,
                                         "detail": "no job 'nope'"})

    with _client(handler) as api, pytest.raises(ApiError, match="HTTP 404: no job 'nope'"):
        api.save_results_csv("nope", tmp_path / "results.csv")
    assert not (tmp_path / "results.csv").exists()

"""A cancelled batch on the page: its state says how many scans had finished and how many were
never run, progress counts finished work only, and each unfinished scan reads cancelled."""

from __future__ import annotations

import re

import cv2
import httpx
from page_driver import KEY, PageDriver
from playwright.sync_api import expect

from prismsynth import Box, render_oblique_view

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def test_a_cancelled_batch_reads_as_it_is(page, stack):
    scene = render_oblique_view(Box(120.0, 80.0, 60.0), seed=1)
    _, jpg = cv2.imencode(".jpg", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR))
    headers = {"X-API-Key": KEY}
    with httpx.Client(base_url=stack.url, headers=headers, timeout=30) as http:
        ref = http.post("/v1/uploads", files={"file": ("box.jpg", jpg.tobytes())}).json()["reference"]
        item = {"image": ref, "points": [list(map(round, scene.points[n])) for n in NAMES],
                "scale": {"kind": "edge", "edge": "width", "length_mm": 120}}
        job_id = http.post("/v1/jobs", json={"items": [item] * 30}).json()["id"]
        cancelled = http.post(f"/v1/jobs/{job_id}/cancel").json()
    done = cancelled["items_done"]

    d = PageDriver(page)
    d.log_in()
    row = page.locator(f"#jobs tr[data-job='{job_id}']")
    expect(row).to_contain_text("cancelled")
    expect(row).to_contain_text(f"{done} of 30")
    row.get_by_role("button").click()
    expect(page.locator("#job-state")).to_have_text(re.compile(
        rf"Job {job_id[:8]}: Cancelled\. {done} of 30 scans had finished; {30 - done} were not run\."))
    expect(page.locator("#job-percent")).to_contain_text(f"{cancelled['progress']} %")
    expect(page.locator("#job-percent")).to_contain_text(f"{done} of 30 scans")
    assert cancelled["progress"] < 100

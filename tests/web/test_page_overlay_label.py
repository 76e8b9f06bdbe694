"""The result's overlay download is named by the format its file is in: a JPEG (overlay.jpg) as
the worker stores it now, a PNG (overlay.png) for a job stored before. A real one-photo job on the
stack; the older job's link is the same job's answer with its overlay link renamed on the way to
the page (the link's file name is all the label reads)."""

from __future__ import annotations

import json
import re
import time

import cv2
import httpx
import pytest
from page_driver import KEY, PageDriver
from playwright.sync_api import Route, expect

from prismsynth import Box, render_oblique_view

BOX = Box(120.0, 80.0, 60.0)


@pytest.fixture(scope="module")
def job(stack) -> dict:
    """A finished one-photo job."""
    with httpx.Client(base_url=stack.url, headers={"X-API-Key": KEY}, timeout=30) as http:
        scene = render_oblique_view(BOX, image_size=(640, 512), focal_px=700.0, seed=21)
        ok, png = cv2.imencode(".png", cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR))
        assert ok
        ref = http.post("/v1/uploads", files={"file": ("part.png", png.tobytes())}).json()["reference"]
        points = {n: list(scene.points[n]) for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")}
        item = {"image": ref, "points": points, "focal_px": scene.focal_px,
                "scale": {"kind": "pinhole", "distance_mm": scene.distance_mm}}
        made = http.post("/v1/jobs", json={"items": [item], "client_reference": "overlay label"})
        assert made.status_code == 202, made.text
        job_id = made.json()["id"]
        deadline = time.monotonic() + 240
        while (found := http.get(f"/v1/jobs/{job_id}").json())["state"] not in ("succeeded", "failed"):
            assert time.monotonic() < deadline, found["state"]
            time.sleep(0.5)
    assert found["state"] == "succeeded", found
    return found


@pytest.mark.parametrize(("stored", "label"), [(None, "JPEG"), ("overlay.png", "PNG")],
                         ids=["jpeg", "png-before"])
def test_the_overlay_link_names_its_files_format(page, job, stored: str | None, label: str) -> None:
    overlay = job["items"][0]["downloads"]["overlay"]
    assert re.search(r"/overlay\.jpg(\?|$)", overlay), overlay

    def older(route: Route) -> None:  # the job as one stored before the overlay was a JPEG
        answer = route.fetch()
        body = answer.json()
        for item in body.get("items", []):
            links = item.get("downloads", {})
            if "overlay" in links:
                links["overlay"] = links["overlay"].replace("/overlay.jpg", f"/{stored}")
        route.fulfill(response=answer, body=json.dumps(body))

    if stored is not None:
        page.route(re.compile(rf"/v1/jobs/{job['id']}(\?.*)?$"), older)
    d = PageDriver(page)
    d.log_in()
    page.get_by_role("button", name=f"Open job {job['id'][:8]} (succeeded)").click()
    expect(page.locator(".downloads a").last).to_have_text(f"Download Fit overlay ({label})")
    link = page.locator(".downloads a").last.get_attribute("href")
    assert link is not None and (stored or "overlay.jpg") in link

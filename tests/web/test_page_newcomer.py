"""Rough edges a newcomer hit on the page with the sample photo (issue 30): what the result says
about a large point loss, the number of points the page starts with, a given figure, formats."""

from __future__ import annotations

import json
import re
from pathlib import Path

import httpx
import pytest
from page_driver import KEY, NO_SCALE, PageDriver
from playwright.sync_api import expect

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "box.jpg"
# samples/job.json's points
POINTS = {"p1": (395, 293), "p2": (943, 331), "p3": (919, 761), "p4": (943, 331), "p5": (1035, 298),
          "p6": (411, 647), "p7": (1009, 660)}


def _sample(d: PageDriver, seven: bool) -> None:
    """Log in, add the sample photo and click its five (or seven) points."""
    d.log_in()
    d.add_photos(SAMPLE)
    extra = d.page.get_by_label("Also mark P6 and P7")
    extra.check() if seven else extra.uncheck()
    for name in ("p1", "p2", "p3", "p4", "p5") + (("p6", "p7") if seven else ()):
        d.click_photo(POINTS[name])
    expect(d.page.locator("#next-point")).to_contain_text("Every point is placed")


def test_a_large_point_loss_is_a_warning(page, stack):
    d = PageDriver(page)
    _sample(d, seven=False)
    page.get_by_label("Method").select_option(label="The paper's colour scan")
    page.get_by_label("Scale", exact=True).select_option(label="One known edge")
    page.get_by_label("Known edge").select_option(label="Width (P1 to P2)")
    page.get_by_label("Its length (mm)").fill("120")
    assert "Done" in d.submit_and_wait()
    expect(page.locator("#result-warnings .warning", has_text="point loss 9")).to_contain_text(
        "of the front face's 257,481")


def _pinhole(page) -> None:
    """samples/job.json's scale: 279.132 mm away at a focal length of 1400 px."""
    page.get_by_label("Scale", exact=True).select_option(label="Shooting distance and focal length")
    page.get_by_label("Shooting distance to the front face (mm)").fill("279.132")
    page.get_by_label("Focal length", exact=False).fill("1400")


def test_csv_and_ply_by_default_and_the_compact_formats_need_a_scale(page, stack):
    d = PageDriver(page)
    _sample(d, seven=True)
    outputs = page.get_by_label("Outputs")
    expect(outputs.locator("option")).to_have_text([
        "The service's default (CSV and PLY unless it was set up otherwise)",
        "Cloud as CSV and PLY (about 23 MB a photo)",
        "Cloud as LAZ, and the box as a glTF model (about 1.3 MB a photo; needs a scale)",
        "All of them: CSV, PLY, LAZ and glTF (needs a scale)",
        "The part for CAD: a STEP solid and its inspection drawing (SVG, PDF, DXF; needs a scale)",
        "LAZ, glTF, the STEP solid and the drawing (needs a scale)"])
    outputs.select_option(value="laz,glb")  # without a scale: said at once, nothing sent
    page.get_by_role("button", name="Submit job").click()
    expect(page.locator("#form-error")).to_contain_text("need a scale")
    outputs.select_option(value="")
    _pinhole(page)
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        assert "Done" in d.submit_and_wait()
    assert "formats" not in json.loads(sent.value.post_data)["items"][0]  # the service's default
    expect(page.locator(".downloads a")).to_have_text(
        [f"Download {name}"
         for name in ("Cloud (CSV)", "Cloud (PLY)", "Report (JSON)", "Fit overlay (JPEG)")])


def test_the_part_for_cad_needs_a_scale_and_downloads_the_solid_and_the_drawing(page, stack):
    d = PageDriver(page)
    _sample(d, seven=True)
    outputs = page.get_by_label("Outputs")
    outputs.select_option(value="step,drawing")  # without a scale: said at once, nothing sent
    page.get_by_role("button", name="Submit job").click()
    expect(page.locator("#form-error")).to_contain_text("the STEP solid and the drawing are in millimetres")
    _pinhole(page)
    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        assert "Done" in d.submit_and_wait()
    assert json.loads(sent.value.post_data)["items"][0]["formats"] == ["step", "drawing"]
    expect(page.locator(".downloads a")).to_have_text(
        [f"Download {name}" for name in ("CAD solid (STEP)", "CAD solid's dimensions (JSON)", "Drawing (PDF)",
                                         "Drawing (SVG)", "Drawing (DXF)", "Report (JSON)",
                                         "Fit overlay (JPEG)")])
    links = page.locator(".downloads a")
    step = httpx.get(links.nth(0).get_attribute("href"))
    assert step.status_code == 200 and step.content.startswith(b"ISO-10303-21;")
    assert step.headers["content-type"] == "model/step"
    pdf = httpx.get(links.nth(2).get_attribute("href"))
    assert pdf.content.startswith(b"%PDF") and pdf.headers["content-type"] == "application/pdf"


def test_a_truncated_jpeg_is_said_to_be_truncated(page, stack, tmp_path):
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(SAMPLE.read_bytes()[:40_000])  # the header whole, most of the scan missing
    d = PageDriver(page)
    d.log_in()
    page.get_by_label("Add photos").set_input_files(str(cut))
    line = page.locator("#photo-list li", has_text="cut.jpg")
    expect(line).to_contain_text("'cut.jpg' is a truncated JPEG (40,000 bytes, cut short before its "
                                 "end-of-image marker)")
    expect(line).to_have_class("error")
    assert "this browser cannot show" not in line.text_content()


def test_the_page_starts_with_seven_points(page, stack):
    # Five points measure the sample as 120 x 94.0 x 20.6 mm (the box is 120 x 80 x 60): the
    # page starts where perspective is corrected, and asks for P6 and P7 after P5.
    d = PageDriver(page)
    d.log_in()
    d.add_photos(SAMPLE)
    expect(page.get_by_label("Also mark P6 and P7")).to_be_checked()
    for name in ("p1", "p2", "p3", "p4", "p5"):
        d.click_photo(POINTS[name])
    expect(page.locator("#next-point")).to_contain_text("Click P6")
    expect(page.locator("#point-table tbody tr")).to_have_count(7)


def test_a_known_edge_is_shown_as_given_not_as_a_measurement(page, stack):
    d = PageDriver(page)
    _sample(d, seven=True)
    page.get_by_label("Scale", exact=True).select_option(label="One known edge")
    page.get_by_label("Known edge").select_option(label="Width (P1 to P2)")
    page.get_by_label("Its length (mm)").fill("120")
    assert "Done" in d.submit_and_wait()
    width = page.locator("#dimensions dd[data-field=width]")
    expect(width).to_have_text("120.00 mm (given)")
    measured = re.compile(r"^\d+\.\d\d ± \d+\.\d\d mm$")
    expect(page.locator("#dimensions dd[data-field=height]")).to_have_text(measured)
    assert width.evaluate("e => getComputedStyle(e).fontWeight") == "400"  # not bold as a result
    expect(page.locator("#viewer .dim-label[data-dim=width]")).to_contain_text("120.00 mm (given)")
    job = httpx.get(f"{stack.url}/v1/jobs?limit=1", headers={"X-API-Key": KEY}).json()["jobs"][0]
    assert job["items"][0]["result"]["given_dimension"] == "width"


def test_the_login_screen_says_what_this_is_and_where_the_key_comes_from(page, stack):
    intro = page.locator("#intro")
    expect(intro).to_be_visible()
    expect(intro).to_contain_text("measures a box-shaped object from one photo")
    expect(intro).to_contain_text("The key comes from whoever runs this service")
    expect(intro).to_contain_text("prism serve prints one when it starts")
    PageDriver(page).log_in()
    expect(intro).to_be_hidden()


SCREENS = [{"width": 1366, "height": 768}, {"width": 1920, "height": 1080}]


@pytest.mark.parametrize("screen", SCREENS, ids=["1366x768", "1920x1080"])
def test_the_photo_to_mark_owns_the_screen(page, stack, screen):
    page.set_viewport_size(screen)
    d = PageDriver(page)
    d.log_in()
    d.add_photos(SAMPLE)
    page.wait_for_function("document.getElementById('marker').dataset.view")
    inside = lambda b: (b["x"] >= 0 and b["y"] >= 0 and b["x"] + b["width"] <= screen["width"]  # noqa: E731
                        and b["y"] + b["height"] <= screen["height"])
    assert page.evaluate("window.scrollY") == 0
    canvas = page.locator("#marker").bounding_box()
    assert inside(canvas), canvas
    # The whole photo is drawn inside the canvas, and large: most of the window.
    scale, ox, oy = d.view()
    shown = (1280 * scale, 1024 * scale)
    assert ox >= -0.5 and oy >= -0.5, (ox, oy)
    assert ox + shown[0] <= canvas["width"] + 0.5 and oy + shown[1] <= canvas["height"] + 0.5, (shown, canvas)
    assert shown[0] * shown[1] >= 0.45 * screen["width"] * screen["height"], (shown, screen)
    # The steps beside it, the prompt and every point to place on the same screen.
    steps = page.locator("section[aria-labelledby=h-photos]").bounding_box()
    assert steps["x"] >= canvas["x"] + canvas["width"], (steps, canvas)
    for heading in ("1. Photos", "2. Reference points"):
        assert inside(page.get_by_role("heading", name=heading).bounding_box()), heading
    assert inside(page.locator("#next-point").bounding_box())
    rows = page.locator("#point-table tbody tr")
    expect(rows).to_have_count(7)
    for i in range(7):
        assert inside(rows.nth(i).bounding_box()), (i, rows.nth(i).bounding_box())
    # Marking all seven needs no scrolling either.
    for name in ("p1", "p2", "p3", "p4", "p5", "p6", "p7"):
        page.mouse.click(canvas["x"] + ox + (POINTS[name][0] + 0.5) * scale,
                         canvas["y"] + oy + (POINTS[name][1] + 0.5) * scale)
    expect(page.locator("#next-point")).to_contain_text("Every point is placed")
    assert page.evaluate("window.scrollY") == 0
    assert abs(float(d.mark("p3")[0]) - POINTS["p3"][0]) <= 1.5 / scale


def test_the_scale_is_chosen_and_a_result_in_pixels_says_so(page, stack):
    # No scale is chosen for the person (issue 37: "None (output in pixels)" was the default, and
    # a scan came back in pixels unsaid): submitting without one is refused on the page, at the
    # field, and nothing is sent. "None" chosen, the result says its dimensions are pixels.
    d = PageDriver(page)
    _sample(d, seven=True)
    scale = page.get_by_label("Scale", exact=True)
    expect(scale).to_have_value("")
    expect(scale.locator("option")).to_have_text([
        "Choose one: it sets the dimensions' unit", NO_SCALE,
        "Millimetres per pixel", "Shooting distance and focal length", "One known edge"])
    sent: list[str] = []
    page.on("request", lambda r: sent.append(r.url) if r.url.endswith("/v1/jobs") and r.method == "POST"
            else None)
    page.get_by_role("button", name="Submit job").click()
    expect(page.locator("#form-error")).to_have_text(
        "Choose a scale under Scale: one known edge, millimetres per pixel, or a shooting distance and focal "
        "length give the dimensions in millimetres; “None” gives them in pixels.")
    expect(scale).to_be_focused()
    expect(page.locator("#settings-panel")).to_have_attribute("open", "")
    assert sent == []

    scale.select_option(label=NO_SCALE)
    assert "Done" in d.submit_and_wait()
    assert len(sent) == 1
    expect(page.locator("#dimensions dd[data-field=height]")).to_have_text(
        re.compile(r"^\d+\.\d\d ± \d+\.\d\d px$"))
    note = page.locator("#pixels-note")
    expect(note).to_be_visible()
    expect(note).to_have_text(
        re.compile(r"^These dimensions are in pixels, not millimetres: the scan had no scale\."))
    expect(page.locator("#result-warnings")).to_contain_text("pixels, not mm")  # the scan's own warning

    # With a scale the note is gone (the settings were folded away under the result).
    page.locator("#settings-panel > summary").click()
    scale.select_option(label="One known edge")
    page.get_by_label("Its length (mm)").fill("120")
    if d.mark("p1") is None:  # the points of a submitted scan were cleared: mark them again
        for name in ("p1", "p2", "p3", "p4", "p5", "p6", "p7"):
            d.click_photo(POINTS[name])
    assert "Done" in d.submit_and_wait()
    expect(page.locator("#dimensions dd[data-field=height]")).to_have_text(re.compile(r" mm$"))
    expect(page.locator("#pixels-note")).to_have_count(0)

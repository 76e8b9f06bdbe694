"""Keyboard and screen-reader basics of the page, and its errors in plain words."""

from __future__ import annotations

import re

from page_driver import KEY, NO_SCALE, PageDriver, save_photo
from playwright.sync_api import expect

from prismsynth import Box, render_oblique_view

LABELLED = ["API key", "Add photos", "One photo (front and side)", "Two photos (front photo, side photo)",
            "Front photo", "Also mark P6 and P7", "Magnifier", "Zoom in", "Zoom out",
            "Pointer position in pixels", "Photo: click to place the next reference point", "P1 x (pixels)",
            "P5 y (pixels)", "Colour tolerance", "Method", "Cloud", "Scale", "Focal length", "Job progress"]
BUTTONS = ["Log out", "Fit", "Undo", "Clear", "Front photo", "Add this scan to the batch", "Submit job",
           "Refresh"]
# Tab goes through the steps in the order they are done (a subsequence: others lie between).
TAB_ORDER = ["Add photos", "One photo", "Front photo", "Also mark P6 and P7", "Front photo", "Zoom in",
             "Undo", "Clear", "Photo: click to place", "P1 x", "P1 y", "P2 x", "Colour tolerance",
             "Method", "Cloud", "Scale", "Focal length", "Add this scan to the batch", "Submit job",
             "Refresh"]
NAME_JS = """() => { const e = document.activeElement;
  return e.getAttribute('aria-label') || (e.labels && e.labels[0] && e.labels[0].textContent.trim())
         || e.textContent.trim(); }"""


def test_controls_are_labelled_and_tab_in_order(page):
    expect(page.get_by_label("API key")).to_be_focused()
    page.keyboard.press("Tab")
    expect(page.get_by_role("button", name="Log in")).to_be_focused()
    page.get_by_label("API key").fill(KEY)
    page.get_by_label("API key").press("Enter")  # the whole flow works from the keyboard
    expect(page.get_by_label("Add photos")).to_be_focused()
    for name in LABELLED:
        expect(page.get_by_label(name, exact=False).first).to_be_attached()
    for name in BUTTONS:
        expect(page.get_by_role("button", name=name, exact=True).first).to_be_visible()
    expect(page.get_by_role("status").first).to_be_attached()
    names = []
    for _ in range(60):
        names.append(page.evaluate(NAME_JS))
        page.keyboard.press("Tab")
    position = 0
    for want in TAB_ORDER:
        found = next((i for i in range(position, len(names)) if names[i].startswith(want)), None)
        assert found is not None, f"{want!r} not reached by Tab after {names[position - 1]!r}: {names}"
        position = found + 1


def test_points_by_keyboard_and_by_typing(page, tmp_path):
    scene = render_oblique_view(Box(100, 70, 50), seed=2)
    d = PageDriver(page)
    d.log_in()
    d.add_photos(save_photo(scene, tmp_path / "box.png"))
    d.click_photo((400.0, 300.0))
    p1 = d.mark("p1")
    canvas = page.get_by_label("Photo: click to place the next reference point")
    canvas.focus()
    canvas.press("ArrowRight")
    canvas.press("Shift+ArrowDown")
    assert d.mark("p1") == (p1[0] + 1, p1[1] + 10)
    canvas.press("Control+z")
    assert d.mark("p1") == (p1[0] + 1, p1[1])
    scale = d.view()[0]
    canvas.press("+")
    assert d.view()[0] > scale
    canvas.press("0")
    assert d.view()[0] == scale
    page.get_by_label("P2 x (pixels)").fill("900")
    page.get_by_label("P2 y (pixels)").fill("320")
    page.get_by_label("P2 y (pixels)").press("Tab")  # typed points count like clicked ones
    assert d.mark("p2") == (900.0, 320.0)
    expect(page.locator("#next-point")).to_have_text("Click P3: front face, lower-right corner.")
    page.get_by_role("button", name="Clear").click()
    assert d.mark("p1") is None and d.mark("p2") is None


def test_errors_are_plain_words(page, tmp_path):
    page.get_by_label("API key").fill("not-a-key")
    page.get_by_role("button", name="Log in").click()
    expect(page.get_by_role("alert").first).to_have_text(
        "The API key was not accepted. Check it and log in again.")
    expect(page.locator("#main")).to_be_hidden()
    d = PageDriver(page)
    d.log_in()
    scene = render_oblique_view(Box(100, 70, 50), seed=2)
    d.add_photos(save_photo(scene, tmp_path / "box.png"))
    # The scale is chosen (the page has no default): the errors below are the points' and tolerance's.
    page.get_by_label("Scale", exact=True).select_option(label=NO_SCALE)
    page.get_by_label("Also mark P6 and P7").uncheck()  # five points
    error = page.locator("#form-error")
    for name in ("p1", "p2", "p3"):
        d.click_photo(scene.points[name])
    page.get_by_role("button", name="Submit job").click()
    expect(error).to_have_text("P4 (where the second face starts: the same corner as P2 for a right "
                               "side face (click P2), or as P1 for a left side face or the top "
                               "(click P1)) is not placed yet.")
    page.get_by_label("Colour tolerance").fill("500")
    page.get_by_role("button", name="Submit job").click()
    expect(error).to_have_text('The colour tolerance must be at most 128 (got "500").')
    page.get_by_label("Colour tolerance").fill("12")
    # Points in the wrong order: the API refuses the job at submit (it knows the photo's size and
    # checks the points as the engine would), and the page says why, pointing at the points.
    for name, (x, y) in {"p4": (700, 500), "p5": (650, 520)}.items():
        page.get_by_label(f"{name.upper()} x (pixels)").fill(str(x))
        page.get_by_label(f"{name.upper()} y (pixels)").fill(str(y))
        page.get_by_label(f"{name.upper()} y (pixels)").press("Tab")
    page.get_by_role("button", name="Submit job").click()
    expect(error).to_have_text(re.compile(
        r"^The service refused the request\. scan 1, points: item 0: cannot tell which face P4, P5 "
        r"and P7 mark: P4 \(700,500\) must be the corner P2 .* or the corner P1 .*"))

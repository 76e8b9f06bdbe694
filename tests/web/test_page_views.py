"""Several photos of one part marked on the page and measured as ONE box by the real stack (issue
20): three photo-like renders of one box (`prismsynth.photo_like_views`: one phone, lens
distortion, JPEG, the focal length unknown to the service), each photo's seven points typed into
the table of points (the renders' own clicks, 0-3 px off the true corners), sent as one item with
`views`; the dimensions shown hold the truth within their shown ± and 3 %, no 3D view is shown
(a joint fit makes no cloud). A photo whose points mark a 15 % deeper box is shown left out with
its reason, as a numbered warning; a 422 from the API is a sentence; a photo taken out of the
part, down to one, brings the one-photo scan back."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from page_driver import PageDriver
from playwright.sync_api import Page, Route, expect

from prismcore.spec import ScanSpec
from prismsynth import PhotoLikeScene, photo_like_views

ARTEFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "web"  # gitignored, for a person
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")
DIMENSIONS = ("width", "height", "depth")


@pytest.fixture(scope="module")
def scenes() -> list[PhotoLikeScene]:
    return photo_like_views(2, 3)  # 1280 x 960; the worker's joint test measures the same box


def _save(scene: PhotoLikeScene, path: Path) -> Path:
    path.write_bytes(scene.jpeg)  # the phone's JPEG as it is
    return path


def _type(page: Page, points: dict[str, tuple[float, float]], names=NAMES) -> None:
    """Type points into the table of points, as a person may instead of clicking."""
    for name in names:
        x, y = points[name]
        page.get_by_label(f"{name.upper()} x (pixels)").fill(repr(float(x)))
        page.get_by_label(f"{name.upper()} y (pixels)").fill(repr(float(y)))
        page.get_by_label(f"{name.upper()} y (pixels)").press("Tab")


def _deeper(points: dict[str, tuple[float, float]], factor: float) -> dict[str, tuple[float, float]]:
    """The points with the second face's far corners pulled out along the depth: a deeper box
    (as tests/service/test_joint_worker.py makes a wrong view)."""
    out = dict(points)
    for far, near in (("p5", "p4"), ("p7", "p3")):
        (fx, fy), (nx, ny) = points[far], points[near]
        out[far] = (nx + factor * (fx - nx), ny + factor * (fy - ny))
    return out


def _shown(page: Page) -> dict[str, tuple[float, float]]:
    """Each dimension as shown and its shown ±."""
    out = {}
    for name in DIMENSIONS:
        text = page.locator(f"#dimensions dd[data-field={name}]").text_content()
        # The known edge is shown as given ("120.00 mm (given)"): its ± is 0.
        value, sigma = re.fullmatch(r"([\d.]+) (?:± ([\d.]+) mm|mm \(given\))", text.strip()).groups()
        out[name] = (float(value), float(sigma or 0.0))
    return out


def _within_truth(page: Page, scene: PhotoLikeScene) -> dict[str, tuple[float, float]]:
    shown = _shown(page)
    for name, (value, sigma) in shown.items():
        true = getattr(scene.box, f"{name}_mm")
        assert abs(value - true) <= sigma + 0.005, (name, value, sigma, true)  # 0.005: the rounding shown
        assert abs(value / true - 1) <= 0.03, (name, value, true)
    return shown


def test_three_photos_of_one_part_measured_as_one_box(page, stack, tmp_path, scenes):
    d = PageDriver(page)
    d.log_in()
    d.add_photos(*[_save(s, tmp_path / f"view{k + 1}.jpg") for k, s in enumerate(scenes)])
    # The first photo chosen is the front photo, whichever decodes first.
    expect(page.locator("#front-photo option:checked")).to_have_text("view1.jpg")
    clicks = [s.clicks for s in scenes]
    status = page.locator("#part-status")
    items = page.locator("#part-list li")
    add = page.get_by_role("button", name="Mark another photo of this part")

    # Photo 1 with five points, as for one photo (P6 and P7 unticked; the page starts with seven):
    # another photo needs all seven.
    page.get_by_label("Also mark P6 and P7").uncheck()
    _type(page, clicks[0], NAMES[:5])
    expect(page.locator("#next-point")).to_have_text(re.compile(r"^Every point is placed"))
    add.click()
    expect(status).to_contain_text("needs all seven points: place P6 and P7 on view1.jpg")
    expect(page.get_by_label("Also mark P6 and P7")).to_be_checked()
    expect(page.locator("#next-point")).to_contain_text("Click P6")
    expect(items).to_have_count(0)
    _type(page, clicks[0], ("p6", "p7"))
    add.click()

    # Photo 2 is shown for its points, the page says which face and corner they go on.
    expect(items).to_have_count(2)
    expect(page.locator("#part-help")).to_be_visible()
    expect(page.locator("#part-help")).to_contain_text("the same front face, with P1 on the same corner")
    expect(page.locator("#next-point")).to_have_text(
        "Photo 2 of 2 of this part (view2.jpg): mark the same front face as on photo 1, with P1 on the "
        "same corner. Click P1: front face, upper-left corner.")
    expect(page.get_by_label("Front photo", exact=True)).to_have_value(
        page.locator("#front-photo option", has_text="view2.jpg").get_attribute("value"))
    expect(items.nth(0)).to_have_text(re.compile(r"^Photo 1: view1\.jpg, 7 of 7 points"))
    expect(items.nth(1)).to_have_text(re.compile(r"^Photo 2: view2\.jpg, 0 of 7 points \(shown\)"))
    expect(page.get_by_label("Also mark P6 and P7")).to_be_disabled()  # a part's photos need all seven
    expect(page.get_by_label("Two photos (front photo, side photo)")).to_be_disabled()
    d.click_photo(clicks[1]["p1"])  # clicked on photo 2's canvas, then typed exactly
    assert d.mark("p1") is not None and abs(d.mark("p1")[0] - clicks[1]["p1"][0]) < 3
    _type(page, clicks[1])
    add.click()
    expect(items).to_have_count(3)
    _type(page, clicks[2])
    expect(items.nth(2)).to_have_text(re.compile(r"^Photo 3: view3\.jpg, 7 of 7 points \(shown\)"))
    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTEFACTS / "views-marked.png"))

    # A known edge is needed: the settings were opened at it; its length is still missing.
    expect(page.get_by_label("Scale", exact=True)).to_have_value("edge")
    page.get_by_role("button", name="Submit job").click()
    expect(page.locator("#form-error")).to_have_text(
        "Several photos of one part are measured as one box, which needs one known edge as the scale: "
        "choose “One known edge” under Scale, which edge it is and its length in mm.")
    expect(page.get_by_label("Its length (mm)")).to_be_focused()
    scene = scenes[0]
    page.get_by_label("Known edge").select_option(scene.known_edge)
    page.get_by_label("Its length (mm)").fill(repr(scene.known_length_mm))

    with page.expect_request(lambda r: r.url.endswith("/v1/jobs") and r.method == "POST") as sent:
        state = d.submit_and_wait(timeout_ms=240_000)
    assert "Done" in state, (state, page.locator("#result").text_content())
    [item] = json.loads(sent.value.post_data)["items"]  # ONE item with the three photos
    spec = ScanSpec.model_validate(item)
    assert spec.views is not None and [v.name for v in spec.views] == ["view1.jpg", "view2.jpg", "view3.jpg"]
    for view, want in zip(spec.views, clicks, strict=True):
        got = view.points.model_dump()
        assert all(got[n] == pytest.approx(want[n]) for n in NAMES)
    assert "points" not in item and "image" not in item and spec.scale.kind == "edge"

    expect(page.locator("#joint-views")).to_have_text("Measured as one box from 3 of 3 photos.")
    shown = _within_truth(page, scene)
    print(f"\nthree photos on the page: {shown}, true {scene.box}")
    expect(page.locator("#joint-table tbody tr")).to_have_count(3)
    expect(page.locator("#joint-table tbody td:nth-child(2)")).to_have_text(["used"] * 3)
    expect(page.locator("#details dd[data-field=focal-length]")).to_contain_text("fitted to every photo")
    # No cloud: no 3D view, no fit on a photo; the joint fit's report to download.
    expect(page.locator("#viewer-box")).to_be_hidden()
    expect(page.locator("#overlay-figure")).to_be_hidden()
    expect(page.locator(".downloads a")).to_have_text(["Download Report (JSON)"])
    expect(page.locator("#warnings")).to_have_count(0)

    # Photo 2 shown again, its points moved to mark a 15 % deeper box: it is left out, named,
    # with its reason, as a numbered warning; the others measure the box.
    page.get_by_role("button", name="Show photo 2 of this part (view2.jpg)").click()
    expect(page.locator("#next-point")).to_contain_text("Photo 2 of 3 of this part (view2.jpg)")
    assert d.mark("p5") == pytest.approx(clicks[1]["p5"])  # its points kept while another was shown
    _type(page, _deeper(clicks[1], 1.15), ("p5", "p7"))
    before = page.locator("#job-state").text_content()
    page.get_by_role("button", name="Submit job").click()
    expect(page.locator("#job-state")).not_to_have_text(before)  # the new job, not the last one's "Done"
    expect(page.locator("#job-state")).to_contain_text(re.compile(r"Done|Failed"), timeout=240_000)
    assert "Done" in page.locator("#job-state").text_content()
    expect(page.locator("#joint-views")).to_have_text(
        "Measured as one box from 2 of 3 photos; 1 left out (see the warning).")
    warning = page.locator("#warnings li.warning")
    expect(warning).to_have_count(1)
    expect(warning).to_have_text(re.compile(
        r"^⚠ 1: view2\.jpg left out: disagrees with the other views beyond its noise .*alone it measures"))
    expect(page.locator("#joint-table tr[data-view='1'] td")).to_have_text(
        ["left out", re.compile(r"^disagrees with the other views beyond its noise")])
    _within_truth(page, scene)
    page.locator("#result").screenshot(path=str(ARTEFACTS / "views-result.png"))

    # A 422 from the API (the known edge taken out of the request on its way): a sentence naming
    # the field, the page still working.
    def drop_scale(route: Route) -> None:
        if route.request.method != "POST":
            return route.continue_()
        body = json.loads(route.request.post_data)
        for one in body["items"]:
            one.pop("scale")
        return route.continue_(post_data=json.dumps(body))

    page.route(re.compile(r".*/v1/jobs$"), drop_scale)
    page.get_by_role("button", name="Submit job").click()
    expect(page.locator("#form-error")).to_have_text(re.compile(
        r"^The service refused the request\. scan 1, scale: .*a joint fit needs one known edge"))
    expect(page.get_by_role("button", name="Submit job")).to_be_enabled()
    page.unroute(re.compile(r".*/v1/jobs$"))

    # Photos taken out of the part: down to one, it is measured alone, as before.
    page.get_by_role("button", name="Remove photo 2 (view2.jpg) from this part").click()
    expect(items).to_have_count(2)
    # The photo shown taken out: the one before it is shown.
    expect(page.locator("#next-point")).to_contain_text("Photo 1 of 2 of this part (view1.jpg)")
    page.get_by_role("button", name="Remove photo 2 (view3.jpg) from this part").click()
    expect(status).to_have_text("One photo left: it is measured alone.")
    expect(page.locator("#part-list")).to_be_hidden()  # with the help: only while a part is marked
    expect(page.locator("#next-point")).to_have_text(re.compile(r"^Every point is placed"))
    assert d.mark("p1") == pytest.approx(clicks[0]["p1"])  # photo 1's points are back
    expect(page.get_by_label("Also mark P6 and P7")).to_be_enabled()
    page.get_by_role("button", name="Add this scan to the batch").click()
    expect(page.locator("#batch li")).to_have_text(re.compile(r"^Scan 1: view1\.jpg Remove"))


def _noisy_png(scene: PhotoLikeScene, path: Path) -> Path:
    """The photo as a PNG with noise in every pixel: the same pixel size, a far larger file, slower
    to decode than the JPEG."""
    image = cv2.imdecode(np.frombuffer(scene.jpeg, np.uint8), cv2.IMREAD_COLOR)
    noise = np.random.default_rng(7).integers(-12, 13, image.shape)
    assert cv2.imwrite(str(path), np.clip(image + noise, 0, 255).astype(np.uint8))
    return path


def test_photos_chosen_together_keep_the_order_chosen(page, stack, tmp_path, scenes):
    """Photos added in one selection are the part's photos in the selection's order, not in the
    order the browser finished decoding them: the first, a large PNG, decodes last."""
    d = PageDriver(page)
    d.log_in()
    big = _noisy_png(scenes[0], tmp_path / "big.png")
    small = _save(scenes[1], tmp_path / "small.jpg")
    assert big.stat().st_size > 20 * small.stat().st_size, (big.stat().st_size, small.stat().st_size)
    d.add_photos(big, small)
    listed = page.locator("#photo-list li")
    expect(listed).to_have_text([re.compile(r"^big\.png "), re.compile(r"^small\.jpg ")])
    expect(page.locator("#front-photo option:checked")).to_have_text("big.png")
    expect(page.locator("#next-point")).to_contain_text("Click P1")
    page.get_by_label("Also mark P6 and P7").check()
    _type(page, scenes[0].clicks)
    page.get_by_role("button", name="Mark another photo of this part").click()
    items = page.locator("#part-list li")
    expect(items).to_have_text([re.compile(r"^Photo 1: big\.png, 7 of 7 points "),
                                re.compile(r"^Photo 2: small\.jpg, 0 of 7 points \(shown\)")])
    expect(page.locator("#part-status")).to_have_text("small.jpg is shown: mark its seven points.")


def test_photo_of_another_size_refused_before_submit(page, stack, tmp_path, scenes):
    """The service measures a part's photos only from one camera at one image size (a 422
    otherwise): the page, which knows each photo's size, refuses another size at once, naming both."""
    d = PageDriver(page)
    d.log_in()
    image = cv2.imdecode(np.frombuffer(scenes[1].jpeg, np.uint8), cv2.IMREAD_COLOR)
    half = tmp_path / "half.jpg"
    assert cv2.imwrite(str(half), cv2.resize(image, (640, 480), interpolation=cv2.INTER_AREA))
    d.add_photos(_save(scenes[0], tmp_path / "view1.jpg"), half)
    page.get_by_label("Also mark P6 and P7").check()
    _type(page, scenes[0].clicks)
    add = page.get_by_role("button", name="Mark another photo of this part")
    status = page.locator("#part-status")
    items = page.locator("#part-list li")
    by = "\u00d7"  # the page's multiplication sign
    size_rule = (f"half.jpg is 640 {by} 480 pixels, this part's photos 1280 {by} 960 (view1.jpg): "
                 "the photos of one part must come from one camera at one image size.")
    add.click()
    expect(status).to_have_text(f"{size_rule} Add a photo of that size, then press this again.")
    expect(items).to_have_count(0)
    expect(page.locator("#front-photo option:checked")).to_have_text("view1.jpg")

    # A photo of the part's size added: it is the next one, the other still left aside.
    page.get_by_label("Add photos").set_input_files(str(_save(scenes[1], tmp_path / "view2.jpg")))
    expect(page.locator("#photo-list li", has_text="uploaded")).to_have_count(3)
    add.click()
    expect(status).to_have_text(f"view2.jpg is shown: mark its seven points. Left aside: {size_rule}")
    expect(items).to_have_count(2)
    # Chosen as the front photo while the part is marked: refused too, view2.jpg stays shown.
    page.get_by_label("Front photo", exact=True).select_option(label="half.jpg")
    expect(status).to_have_text(size_rule)
    expect(page.locator("#front-photo option:checked")).to_have_text("view2.jpg")
    expect(items).to_have_count(2)
    expect(items.nth(1)).to_have_text(re.compile(r"^Photo 2: view2\.jpg, 0 of 7 points \(shown\)"))

"""The overlay picture: outlines where the fitted faces are (to sub-pixel), labels beside the
clicks, the photo untouched away from the drawing, and the report adapter's choices."""

from __future__ import annotations

import copy

import cv2
import numpy as np
import pytest

from prismcore import InputError
from prismcore.outputs.overlay import (
    CLICK_COLOR,
    FACE_COLORS,
    LABEL_COLOR,
    RESIDUAL_COLOR,
    draw_overlay,
)
from prismcore.outputs.overlay_report import overlay_from_report, report_notes
from prismcore.report import ScanReport

SIZES = [(240, 320), (480, 640), (1024, 1280), (3000, 4000)]
# single-photo geometry as fractions of (width, height): the box sits left of centre, so the
# right third of the picture is far from anything drawn when there is no legend
FRONT = np.array([[0.14, 0.30], [0.42, 0.33], [0.41, 0.72], [0.15, 0.68]])
SIDE = np.array([[0.42, 0.33], [0.50, 0.28], [0.49, 0.64], [0.41, 0.72]])


def _photo(h: int, w: int, seed: int = 0) -> np.ndarray:
    """Grey-ish noise (90..150): no pixel is close to any overlay colour or to white."""
    rng = np.random.default_rng(seed)
    return rng.integers(90, 151, size=(h, w, 3), dtype=np.uint8)


def _geometry(h: int, w: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    scale = np.array([w, h], dtype=np.float64)
    faces = {"front": FRONT * scale, "side": SIDE * scale}
    f, s = faces["front"], faces["side"]
    clicks = {"p1": f[0], "p2": f[1], "p3": f[2], "p6": f[3], "p4": s[0], "p5": s[1], "p7": s[2]}
    return clicks, faces


def _near(picture: np.ndarray, xy: np.ndarray, color: tuple[int, int, int], reach: int = 1) -> int:
    """The smallest max-channel difference to `color` in the (2 reach + 1)^2 pixels around xy."""
    x, y = (round(float(v)) for v in xy)
    patch = picture[y - reach:y + reach + 1, x - reach:x + reach + 1].astype(int)
    return int(np.abs(patch - np.array(color)).max(axis=2).min())


def _distance_to(h: int, w: int, clicks: dict, faces: dict) -> np.ndarray:
    """Distance (px) from every pixel to the nearest face edge or click: an independent map of
    where the drawing is, built with OpenCV's distance transform."""
    mask = np.full((h, w), 255, np.uint8)
    for quad in faces.values():
        cv2.polylines(mask, [np.rint(quad).astype(np.int32).reshape(-1, 1, 2)], True, 0, 1)
    for p in clicks.values():
        mask[round(float(p[1])), round(float(p[0]))] = 0
    return cv2.distanceTransform(mask, cv2.DIST_L2, 5)


def _inputs(kind: str, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """The image handed in, and the uint8 RGB picture it stands for (the untouched oracle)."""
    base = _photo(h, w)
    if kind == "uint8":
        return base, base
    if kind == "float32":  # a 16-bit photo as load_image returns it: 0..255 with fractions
        rng = np.random.default_rng(1)
        image = base.astype(np.float32) + rng.uniform(-0.45, 0.45, base.shape).astype(np.float32)
        return image, np.clip(np.rint(image), 0, 255).astype(np.uint8)
    grey = base[:, :, 0]
    return grey, np.repeat(grey[:, :, None], 3, axis=2)


@pytest.mark.parametrize(("h", "w"), SIZES)
@pytest.mark.parametrize("kind", ["uint8", "float32", "grey"])
def test_outlines_lie_on_the_edges_and_the_rest_is_the_photo(h, w, kind):
    image, oracle = _inputs(kind, h, w)
    clicks, faces = _geometry(h, w)
    before = image.copy()
    picture = draw_overlay(image, clicks, faces)
    assert picture.shape == (h, w, 3) and picture.dtype == np.uint8
    np.testing.assert_array_equal(image, before)  # drawn on a copy
    for name, quad in faces.items():
        for i in range(4):
            a, b = quad[i], quad[(i + 1) % 4]
            # the edge the faces share (the side's left) carries the front's colour
            want = FACE_COLORS["front"] if name == "side" and i == 3 else FACE_COLORS[name]
            for t in np.linspace(0.3, 0.7, 9):
                assert _near(picture, a + t * (b - a), want) <= 12, (name, i, t)
    far = _distance_to(h, w, clicks, faces) > 0.12 * max(h, w) + 40
    assert far[:, int(0.75 * w):].all()  # the test's own premise: the right quarter is far
    np.testing.assert_array_equal(picture[far], oracle[far])


@pytest.mark.parametrize("offset", [0.0, 0.25, 0.5, 0.75])
def test_outlines_are_placed_to_a_fraction_of_a_pixel(offset):
    black = np.zeros((200, 200, 3), np.uint8)
    x = 100.0 + offset
    picture = draw_overlay(black, {}, {"front": [[40, 40], [x, 40], [x, 160], [40, 160]]})
    # the blue channel across the right edge, halfway down: its centroid is the edge
    row = picture[100, 85:116, 2].astype(float)
    centroid = float((np.arange(85, 116) * row).sum() / row.sum())
    assert centroid == pytest.approx(x, abs=0.1)


@pytest.mark.parametrize(("h", "w"), SIZES)
def test_each_click_has_a_label_beside_it_and_nowhere_else(h, w):
    clicks, faces = _geometry(h, w)
    picture = draw_overlay(_photo(h, w), clicks, faces)
    # anti-aliased text rarely reaches pure white; nothing else drawn (or in the photo) is
    # within 25 of it in every channel
    white = np.all(picture >= np.array(LABEL_COLOR) - 25, axis=2)
    reach = 0.08 * max(h, w) + 40
    yy, xx = np.mgrid[:h, :w]
    near_any = np.zeros((h, w), bool)
    for name, p in clicks.items():
        near = (xx - p[0]) ** 2 + (yy - p[1]) ** 2 <= reach**2
        assert white[near].sum() >= 6, name
        near_any |= near
    assert not white[~near_any].any()

    # each click is a cross: the click colour on all four arms, within a few percent of the photo
    for name, p in clicks.items():
        for d in np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]):
            steps = np.arange(2.0, 0.025 * max(h, w) + 12)
            assert min(_near(picture, p + k * d, CLICK_COLOR) for k in steps) <= 6, (name, d)


def _red(picture: np.ndarray) -> int:
    return int(np.all(np.abs(picture.astype(int) - RESIDUAL_COLOR) <= 12, axis=2).sum())


@pytest.mark.parametrize(
    ("shift", "residuals", "red_line"),
    [
        ((8.0, 6.0), None, True),  # 10 px from its corner: a red line and the value
        ((2.0, 1.5), None, False),  # 2.5 px: within warn_px
        ((8.0, 6.0), {"p3": 0.5}, False),  # the fit's own residual says it is fine
        ((8.0, 6.0), {}, False),  # no residuals at all
        ((0.0, 0.0), {"p3": 7.0}, False),  # flagged by the fit, but nothing to join: label only
    ],
)
def test_a_click_far_from_its_fitted_corner_gets_a_red_line(shift, residuals, red_line):
    h, w = 480, 640
    clicks, faces = _geometry(h, w)
    corner = faces["front"][2]
    clicks["p3"] = corner + np.array(shift)
    picture = draw_overlay(_photo(h, w), clicks, faces, residuals=residuals)
    midway = (clicks["p3"] + corner) / 2
    assert (_near(picture, midway, RESIDUAL_COLOR) <= 12) == red_line
    flagged = red_line or (residuals or {}).get("p3", 0) > 3
    assert (_red(picture) > 0) == flagged  # the label's red box, and the line when drawn


@pytest.mark.parametrize(
    ("image", "clicks", "faces", "needle"),
    [
        (np.zeros((20, 30, 4), np.uint8), {}, {}, "(20, 30, 4)"),
        (np.zeros((20, 30, 3), np.complex64), {}, {}, "complex64"),
        (np.full((20, 30, 3), np.nan, np.float32), {}, {}, "NaN"),
        (np.zeros((20, 30, 3), np.uint8), {"p9": (1, 2)}, {}, "'p9'"),
        (np.zeros((20, 30, 3), np.uint8), {"p1": (1, float("nan"))}, {}, "nan"),
        (np.zeros((20, 30, 3), np.uint8), {"p1": (1, 2, 3)}, {}, "(1, 2, 3)"),
        (np.zeros((20, 30, 3), np.uint8), {}, {"top": np.zeros((4, 2))}, "'top'"),
        (np.zeros((20, 30, 3), np.uint8), {}, {"front": [[0, 0], [1, 1], [2, 2]]},
         "[[0, 0], [1, 1], [2, 2]]"),
    ],
)
def test_bad_input_is_an_input_error_quoting_it(image, clicks, faces, needle):
    with pytest.raises(InputError) as err:
        draw_overlay(image, clicks, faces)
    assert needle in str(err.value)


def test_a_photo_too_small_for_the_legend_gets_none():
    h, w = 60, 80
    clicks, faces = _geometry(h, w)
    bare = draw_overlay(_photo(h, w), clicks, faces)
    noted = draw_overlay(_photo(h, w), clicks, faces, notes=["width 120.00 ± 0.30 mm"] * 6)
    np.testing.assert_array_equal(bare, noted)


def test_the_legend_goes_where_it_hides_nothing():
    h, w = 480, 640
    clicks, faces = _geometry(h, w)
    photo = _photo(h, w)
    bare = draw_overlay(photo, clicks, faces)
    noted = draw_overlay(photo, clicks, faces, notes=["width 120.00 mm", "height 80.00 mm"],
                         alerts=["1 warning"], title="PrismCloud fit")
    changed = np.any(noted != bare, axis=2)
    ys, xs = np.nonzero(changed)
    # one panel in a corner, away from the box (which fills the left-centre of the photo)
    assert ys.min() < 0.1 * h and (xs.min() < 0.1 * w or xs.max() > 0.9 * w)
    panel = np.zeros_like(changed)
    panel[ys.min():ys.max() + 1, xs.min():xs.max() + 1] = True
    assert changed.sum() > 0.3 * panel.sum()  # a filled panel, not scattered changes
    dist = _distance_to(h, w, clicks, faces)
    assert dist[panel].min() > 20  # it covers no face edge and no click


# --- the report adapter -----------------------------------------------------------------------

def _report(h: int = 480, w: int = 640, *, two_photo: bool = False) -> dict:
    """A report.json's content without the optional blocks (no fit, uncertainty or camera)."""
    clicks, faces = _geometry(h, w)
    points = {n: [float(v) for v in np.rint(p)] for n, p in clicks.items()}
    return {
        "points": 1000,
        "dimensions": {"width": 120.0123, "height": 79.9933, "depth": 59.9909, "unit": "mm"},
        "method": "default",
        "faces": {n: {"corners": np.round(q, 3).tolist(), "object_pixels": 900, "marked_pixels": 1000,
                      "point_loss": 0.1} for n, q in faces.items()},
        "warnings": [],
        "timings_ms": {},
        "images": [{"width": w, "height": h}] * (2 if two_photo else 1),
        "inputs": {"image": "a.jpg", "side_image": "b.jpg" if two_photo else None,
                   "points": points, "method": "default"},
    }


def _typed(report: dict) -> ScanReport:
    """The report the adapter reads: report.json's content as `ScanReport`."""
    return ScanReport.model_validate(report)


def test_notes_of_a_report_without_the_optional_fields():
    assert report_notes(_typed(_report())) == ["width 120.01 mm", "height 79.99 mm", "depth 59.99 mm"]


def test_notes_of_a_report_with_every_field():
    report = _report()
    report |= {"uncertainty": {"width": 0.314, "height": 0.2, "depth": 0.555},
               "camera": {"focal_px": 1400.4, "focal_source": "exif", "principal_point": [320, 240]},
               "fit": {"rms_px": 0.834},
               "method": "paper", "frame": {"index": 12, "time_s": 0.48}}
    assert report_notes(_typed(report)) == [
        "width 120.01 ± 0.31 mm", "height 79.99 ± 0.20 mm", "depth 59.99 ± 0.56 mm",
        "focal 1400 px (exif)", "fit RMS 0.83 px", "paper method (no perspective correction)",
        "frame 12 at 0.48 s",
    ]


def test_the_adapter_draws_what_the_report_holds():
    report = _report()
    photo = _photo(480, 640)
    points = report["inputs"]["points"]
    corners = {n: f["corners"] for n, f in report["faces"].items()}
    want = draw_overlay(photo, points, corners, title="PrismCloud fit",
                        notes=[*report_notes(_typed(report)), "no warnings"])
    np.testing.assert_array_equal(overlay_from_report(photo, _typed(report)), want)
    report["warnings"] = ["one", "two"]
    want = draw_overlay(photo, points, corners, title="PrismCloud fit", notes=report_notes(_typed(report)),
                        alerts=["2 warnings (see report.json)"])
    np.testing.assert_array_equal(overlay_from_report(photo.astype(np.float32), _typed(report)), want)


def test_the_adapter_reads_the_fits_residuals():
    report = _report()
    names = ["p1", "p2", "p3", "p4", "p5", "p6", "p7"]
    values = [0.1, 0.2, 9.5, 0.3, 0.4, 0.5, 0.6]
    report["fit"] = {"point_residuals_px": dict(zip(names, values, strict=True))}
    photo = _photo(480, 640)
    corners = {n: f["corners"] for n, f in report["faces"].items()}
    want = draw_overlay(photo, report["inputs"]["points"], corners, title="PrismCloud fit",
                        notes=[*report_notes(_typed(report)), "no warnings"],
                        residuals=dict(zip(names, values, strict=True)))
    got = overlay_from_report(photo, _typed(report))
    np.testing.assert_array_equal(got, want)
    assert _red(got) > 0  # p3's 9.5 px shows, although its click sits on its corner


def test_paper_regions_are_not_taken_for_residuals():
    report = _report()
    report["method"] = "paper"
    f = np.array(report["faces"]["front"]["corners"])
    report["faces"]["front"]["corners"] = [[f[0, 0], f[0, 1]], [f[1, 0], f[0, 1]], [f[1, 0], f[2, 1]],
                                           [f[0, 0], f[2, 1]]]  # axis-aligned, off the clicks
    assert _red(overlay_from_report(_photo(480, 640), _typed(report))) == 0


def test_two_photos_each_show_their_own_clicks_and_face():
    report = _report(two_photo=True)
    photo = _photo(480, 640)
    pts, corners = report["inputs"]["points"], {n: f["corners"] for n, f in report["faces"].items()}
    notes = [*report_notes(_typed(report)), "no warnings"]
    front = overlay_from_report(photo, _typed(report), photo="front")
    side = overlay_from_report(photo, _typed(report), photo="side")
    want_front = draw_overlay(photo, {n: pts[n] for n in ("p1", "p2", "p3", "p6")},
                              {"front": corners["front"]}, notes=notes,
                              title="PrismCloud fit - front photo")
    want_side = draw_overlay(photo, {n: pts[n] for n in ("p4", "p5", "p7")}, {"side": corners["side"]},
                             notes=notes, title="PrismCloud fit - side photo")
    np.testing.assert_array_equal(front, want_front)
    np.testing.assert_array_equal(side, want_side)
    side_colour = np.all(np.abs(front.astype(int) - FACE_COLORS["side"]) <= 12, axis=2)
    front_colour = np.all(np.abs(side.astype(int) - FACE_COLORS["front"]) <= 12, axis=2)
    assert not side_colour.any() and not front_colour.any()


def test_an_undistorted_fit_is_drawn_on_the_undistorted_photo():
    from prismcore.camera import CameraModel, undistort_image, undistort_points

    h, w = 480, 640
    camera = CameraModel(fx=600.0, fy=600.0, cx=319.5, cy=239.5, dist=[-0.12, 0.02, 0.0, 0.0],
                         image_width=w, image_height=h)
    report = _report(h, w)
    report["inputs"]["camera"] = camera.model_dump(mode="json")
    report["camera"] = {"focal_px": 600.0, "focal_source": "camera", "principal_point": [319.5, 239.5],
                        "undistorted": True}
    photo = _photo(h, w)
    names = list(report["inputs"]["points"])
    raw = np.array([report["inputs"]["points"][n] for n in names])
    moved = dict(zip(names, undistort_points(raw, camera), strict=True))
    assert max(np.linalg.norm(moved[n] - raw[i]) for i, n in enumerate(names)) > 5  # premise
    corners = {n: f["corners"] for n, f in report["faces"].items()}
    want = draw_overlay(undistort_image(photo, camera), moved, corners, title="PrismCloud fit",
                        notes=[*report_notes(_typed(report)), "drawn on the undistorted photo",
                               "no warnings"])
    np.testing.assert_array_equal(overlay_from_report(photo, _typed(report)), want)
    del report["inputs"]["camera"]
    with pytest.raises(InputError, match=r"inputs\.camera"):
        overlay_from_report(photo, _typed(report))


@pytest.mark.parametrize(
    ("change", "kw", "needle"),
    [
        (lambda r: None, {"photo": "side"}, "single-photo"),
        (lambda r: None, {"photo": "top"}, "'top'"),
        (lambda r: r["images"].__setitem__(0, {"width": 641, "height": 480}), {}, "641x480"),
        (lambda r: r["inputs"].pop("points"), {}, "inputs.points"),
        (lambda r: r["faces"].pop("side"), {}, "side face"),
    ],
)
def test_the_adapter_refuses_a_report_that_does_not_fit(change, kw, needle):
    report = copy.deepcopy(_report())
    change(report)
    with pytest.raises(InputError) as err:
        overlay_from_report(_photo(480, 640), _typed(report), **kw)
    assert needle in str(err.value)

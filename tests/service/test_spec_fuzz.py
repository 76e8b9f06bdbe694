"""Hypothesis over the job specification and the reference points.

* The engine, on a real render: any points and options give a finite result or an InputError
  (the message an item fails with), never another exception.
* The API, in process on the real Redis and SeaweedFS: any job body (fields valid, invalid or of
  the wrong type) is answered 202 or a 422 whose every entry says where and why; never a 5xx.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from prism_common.settings import get_settings
from pydantic import ValidationError

from prism_api.main import create_app
from prismcore import InputError, ScanSpec, run_scan
from prismcore.report import report_dict

from .conftest import API_KEYS
from .faultstack import item, tiny_scene
from .test_api import photo

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "Using `httpx` with `starlette.testclient`")
    from fastapi.testclient import TestClient

SCENE = tiny_scene(1)
H, W = SCENE.image.shape[:2]
coordinate = st.floats(-40, max(W, H) + 40, allow_nan=False)
point = st.tuples(coordinate, coordinate)
# Near the true corners (the usual case, and where the interesting failures are) or anywhere.
near = st.sampled_from(["p1", "p2", "p3", "p4", "p5", "p6", "p7"]).flatmap(
    lambda n: st.tuples(st.floats(-6, 6), st.floats(-6, 6)).map(
        lambda d, n=n: (SCENE.points[n][0] + d[0], SCENE.points[n][1] + d[1])))
points = st.one_of(st.lists(st.one_of(point, near), min_size=5, max_size=5),
                   st.lists(st.one_of(point, near), min_size=7, max_size=7),
                   st.builds(lambda d: [(SCENE.points[n][0] + d, SCENE.points[n][1] - d) for n in
                                        ("p1", "p2", "p3", "p4", "p5", "p6", "p7")], st.floats(-8, 8)),
                   st.just([(50.0, 50.0)] * 5))  # a region of zero pixels
scales = st.one_of(
    st.none(), st.builds(lambda f: {"kind": "mm_per_px", "front": f}, st.floats(1e-3, 10)),
    st.builds(lambda d: {"kind": "pinhole", "distance_mm": d}, st.floats(10, 5000)),
    st.builds(lambda w: {"kind": "edge", "edge": "width", "length_mm": w}, st.floats(1, 1000)))


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(pts=points, tolerance=st.floats(0, 128), method=st.sampled_from(["default", "paper"]),
       scale=scales, focal=st.one_of(st.none(), st.floats(50, 5000)),
       cloud=st.sampled_from(["surface", "volume"]))
def test_any_points_give_a_result_or_an_input_error(pts, tolerance, method, scale, focal, cloud, figures):
    fields = {"image": "x", "points": [list(p) for p in pts], "tolerance": tolerance, "method": method,
              "cloud": cloud, "max_points": 2_000_000}
    if scale is not None:
        fields["scale"] = scale
    if focal is not None:
        fields["focal_px"] = focal
    figures["inputs tried"] += 1
    try:
        spec = ScanSpec.model_validate(fields)
    except ValidationError:
        return  # the API's 422 (checked below)
    try:
        result = run_scan(spec, SCENE.image)
    except InputError as exc:
        assert str(exc) and "\n" not in str(exc)  # one line, as the item's error
        return
    assert result.cloud.points.dtype == np.float32 or np.issubdtype(result.cloud.points.dtype, np.floating)
    assert np.isfinite(result.cloud.points).all()
    dims = report_dict(result.report)["dimensions"]
    assert all(math.isfinite(v) and v >= 0 for k, v in dims.items() if k != "unit"), dims


# -- through the API ----------------------------------------------------------------------------
# Finite floats only: NaN and infinity are not JSON (test_api sends them as raw bodies).
anything = st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12),
                     st.floats(allow_nan=False, allow_infinity=False),
                     st.text(max_size=30), st.lists(st.integers(-5, 5000), max_size=8))
FIELDS = ("image", "side_image", "points", "tolerance", "method", "scale", "focal_px",
          "principal_point", "formats", "cloud", "max_pixels", "max_points", "csv", "ply_ascii",
          "frames", "frame_points", "views", "fit")
# A video's frame selection and per-frame points: in range, out of it, and of the wrong shape.
selections = st.fixed_dictionaries({}, optional={
    "every": st.integers(-2, 50), "start_s": st.floats(-5, 100), "end_s": st.floats(-5, 100),
    "sharpest": st.integers(-1, 2000), "indices": st.lists(st.integers(-3, 5000), max_size=6),
    "bogus": anything})
frame_points = st.dictionaries(st.one_of(st.integers(-3, 3000).map(str), st.text(max_size=4)),
                               points.map(lambda p: [list(x) for x in p]), max_size=3)
# Several views of one part (a joint fit): of the right shape or not, with a sound scale or not.
# "REF" becomes the test's upload, so the views get past the reference check to their points.
views = st.lists(st.fixed_dictionaries({"image": st.one_of(st.just("REF"), anything),
                                        "points": st.one_of(points.map(lambda p: [list(x) for x in p]),
                                                            st.just("auto"), anything)},
                                       optional={"side_face": st.sampled_from(["right", "top", "back"]),
                                                 "name": anything}), max_size=4)
fits = st.sampled_from(["frames", "joint", "both"])


@pytest.fixture
def client(settings, objects):
    app = create_app()
    app.dependency_overrides[get_settings] = lambda: settings
    with TestClient(app) as client:
        yield client


@pytest.fixture
def reference(client) -> str:
    """A real upload of the tenant's, so that bodies get past the reference check to the rest."""
    r = client.post("/v1/uploads", files={"file": ("box.png", photo())},
                    headers={"X-API-Key": API_KEYS["acme"]})
    assert r.status_code in (200, 201), r.text  # 200: the same content again
    return r.json()["reference"]


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_any_job_body_is_202_or_a_readable_422(client, reference, data, figures):
    body_item = item(reference, SCENE)
    for name in data.draw(st.lists(st.sampled_from(FIELDS), max_size=3, unique=True)):
        choice = data.draw(st.one_of(anything, points.map(lambda p: [list(x) for x in p]), scales,
                                     selections, frame_points, views, fits))
        body_item[name] = choice
    drawn = body_item.get("views")
    for view in drawn if isinstance(drawn, list) else []:
        if isinstance(view, dict) and view.get("image") == "REF":
            view["image"] = reference
    if data.draw(st.booleans()):
        body_item.pop(data.draw(st.sampled_from(sorted(body_item))))
    body = {"items": [body_item] * data.draw(st.integers(0, 3)),
            **data.draw(st.fixed_dictionaries({}, optional={"client_reference": anything,
                                                            "webhook_url": anything}))}
    r = client.post("/v1/jobs", json=body, headers={"X-API-Key": API_KEYS["acme"]})
    figures["inputs tried"] += 1
    figures["5xx seen"] += r.status_code >= 500
    assert r.status_code in (202, 422), r.text
    if r.status_code == 422:
        errors = r.json()["errors"]
        assert errors and all(e["detail"] and isinstance(e["pointer"], str) for e in errors), errors

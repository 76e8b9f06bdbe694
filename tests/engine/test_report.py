"""report.json as a typed model (`prismcore.report.ScanReport`): every mode's real report, as its
writer puts it, validates against the published JSON Schema (docs/reference/report.schema.json),
reads back into the model unchanged, and has exactly the keys its mode sets; the published schema
is the model's; a station's report is its own (its fit's dimensions), not the cloud's."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import jsonschema
import numpy as np
import pytest

import prismcore.station.scan as station_scan
from prismcore import InputError, ScanSpec, run_scan
from prismcore.camera import CameraModel
from prismcore.io import load_image
from prismcore.locate import resolve_points, scan_found
from prismcore.outputs import report_bytes, write_outputs
from prismcore.report import FrameInfo, ScanReport, report_dict, report_schema
from prismcore.station import calibrate_station, scan_on_board, scan_on_station
from prismsynth import Box, render_front_view, render_side_view
from prismsynth.station import StationScene, station_scene

ROOT = Path(__file__).resolve().parents[2]
PUBLISHED = ROOT / "docs" / "reference" / "report.schema.json"
SAMPLE = ROOT / "samples" / "box.jpg"
POINTS = [[395, 293], [943, 331], [919, 761], [943, 331], [1035, 298], [411, 647], [1009, 660]]

# The keys every photo scan's report has, and what each mode adds to them.
PHOTO = {"points", "dimensions", "uncertainty", "camera", "fit", "point_loss", "method", "side_face", "cloud",
         "perspective_corrected", "faces", "warnings", "timings_ms", "images", "inputs", "engine_version",
         "quality"}
FOUND = {"points_source", "auto_points"}
STATION = {"scale_source", "points_source", "station", "engine_dimensions"}
REFUSED = {"dimensions", "uncertainty", "warnings", "timings_ms", *STATION}


class DictSink:
    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}

    def put(self, name: str, data: bytes | Callable, media_type: str) -> None:
        if isinstance(data, bytes):
            self.files[name] = data
            return
        import io

        buf = io.BytesIO()
        data(buf)
        self.files[name] = buf.getvalue()


def _written(result, spec: ScanSpec, images: list[np.ndarray]) -> dict:
    """report.json as `write_outputs` puts it (the writers' timings in), parsed."""
    sink = DictSink()
    write_outputs(result, sink, spec=spec, images=images)
    return json.loads(sink.files["report.json"])


def _sample_spec(**extra: object) -> ScanSpec:
    return ScanSpec.model_validate({"image": "box.jpg", "points": POINTS, "formats": ["csv"], **extra})


@pytest.fixture(scope="module")
def sample() -> np.ndarray:
    return load_image(SAMPLE)


@pytest.fixture(scope="module")
def schema() -> dict:
    return json.loads(PUBLISHED.read_text())


def _station_scene() -> tuple[StationScene, CameraModel]:
    sc = station_scene(4)
    su = sc.setup
    w, h = su.image_size
    camera = CameraModel(fx=su.K[0, 0], fy=su.K[1, 1], cx=su.K[0, 2], cy=su.K[1, 2],
                         dist=[float(v) for v in su.dist], image_width=w, image_height=h)
    return sc, camera


@pytest.fixture(scope="module")
def on_station():
    sc, camera = _station_scene()
    station = calibrate_station(sc.setup.board, sc.plate, camera=camera, plate=sc.plate)
    return sc, station


def _modes(sample: np.ndarray, on_station) -> dict[str, tuple[dict, set[str]]]:
    """Each mode's report.json content, and the keys it must have."""
    out: dict[str, tuple[dict, set[str]]] = {}
    spec = _sample_spec(focal_px=1400, scale={"kind": "pinhole", "distance_mm": 279.132})
    out["photo"] = _written(run_scan(spec, sample), spec, [sample]), PHOTO
    spec = _sample_spec(scale={"kind": "edge", "edge": "width", "length_mm": 120}, nominal=[120, 80, 60],
                        tolerance_mm=0.5)
    out["photo with a nominal"] = _written(run_scan(spec, sample), spec, [sample]), PHOTO
    spec = _sample_spec()
    out["photo in px"] = _written(run_scan(spec, sample), spec, [sample]), PHOTO
    spec = ScanSpec.model_validate({"image": "box.jpg", "points": POINTS[:5], "method": "paper",
                                    "scale": {"kind": "mm_per_px", "front": 0.15}})
    out["paper"] = _written(run_scan(spec, sample), spec, [sample]), PHOTO
    auto = ScanSpec.model_validate({"image": "box.jpg", "points": "auto", "formats": ["csv"],
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120}})
    found_spec, found = resolve_points(auto, sample)
    result = scan_found(found_spec, found.report(), sample)
    out["found"] = _written(result, found_spec, [sample]), PHOTO | FOUND
    # a video frame: measured as a photo, its frame's place added (as `prism scan VIDEO` and the worker do)
    spec = _sample_spec(scale={"kind": "edge", "edge": "width", "length_mm": 120})
    frame = run_scan(spec, sample)
    frame.report.frame = FrameInfo(index=12, time_s=0.48)
    out["video frame"] = _written(frame, spec, [sample]), PHOTO | {"frame"}
    box = Box(120.0, 80.0, 60.0)
    front = render_front_view(box, image_size=(640, 512), focal_px=700.0, seed=7)
    side = render_side_view(box, image_size=(640, 512), focal_px=700.0, seed=7)
    two = ScanSpec.model_validate({"image": "f", "side_image": "s", "formats": ["csv"],
                                   "points": [list(map(float, p)) for p in
                                              [front.points[n] for n in ("p1", "p2", "p3")]
                                              + [side.points["p4"], side.points["p5"]]],
                                   "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0}})
    out["two photos"] = _written(run_scan(two, front.image, side.image), two,
                                 [front.image, side.image]), PHOTO
    sc, station = on_station
    done = scan_on_station(sc.photo, station, "part.jpg", {"formats": ["csv"]})
    assert done.result is not None and done.spec is not None
    out["station"] = _written(done.result, done.spec, [sc.photo]), PHOTO | STATION
    board = scan_on_board(sc.photo, sc.setup.board, None, "part.jpg", {"formats": ["csv"]})
    assert board.result is not None and board.spec is not None
    out["board"] = _written(board.result, board.spec, [sc.photo]), PHOTO | STATION
    return out


@pytest.fixture(scope="module")
def reports(sample, on_station) -> dict[str, tuple[dict, set[str]]]:
    return _modes(sample, on_station)


def test_the_published_schema_is_the_models(schema):
    assert schema == report_schema(), ("docs/reference/report.schema.json is stale: "
                                       ".venv/bin/prism schema --report > docs/reference/report.schema.json")


def test_the_published_schema_is_a_valid_draft_2020_12_schema(schema):
    jsonschema.Draft202012Validator.check_schema(schema)


MODES = ["photo", "photo with a nominal", "photo in px", "paper", "found", "video frame", "two photos",
         "station", "board"]


@pytest.mark.parametrize("mode", MODES)
def test_every_modes_report_validates_against_the_published_schema(reports, schema, mode):
    content, _ = reports[mode]
    jsonschema.Draft202012Validator(schema).validate(content)


@pytest.mark.parametrize("mode", MODES)
def test_every_modes_report_reads_back_unchanged_with_its_modes_keys(reports, mode):
    content, keys = reports[mode]
    assert set(content) == keys
    again = report_dict(ScanReport.model_validate_json(json.dumps(content)))
    assert again == content
    assert json.dumps(again, sort_keys=True) == json.dumps(content, sort_keys=True)  # ints stay ints


def test_the_mode_specific_blocks(reports):
    assert reports["photo"][0]["quality"] is None
    assert reports["photo with a nominal"][0]["quality"]["verdict"] in ("pass", "fail", "uncertain")
    assert reports["photo in px"][0]["dimensions"]["unit"] == "px"
    assert reports["found"][0]["auto_points"]["confidence"] > 0.5
    assert reports["video frame"][0]["frame"] == {"index": 12, "time_s": 0.48}
    on_station = reports["station"][0]["station"]
    assert "verification" in on_station and "drift" in on_station
    assert "verification" not in reports["board"][0]["station"]  # a hand-held board has no station to verify
    assert reports["board"][0]["scale_source"] == "board"


def test_a_station_report_is_the_stations_own(on_station):
    sc, station = on_station
    done = scan_on_station(sc.photo, station, "part.jpg", {"formats": ["csv"]})
    report = done.report
    assert done.result is not None and done.result.report is report  # the files written say the same
    assert report.station is not None and report.dimensions == report.station.dimensions
    assert report.uncertainty == report.station.uncertainty
    # the cloud's scan of the derived points measured its own size: kept apart, not the report's
    assert done.spec is not None
    cloud = run_scan(done.spec, sc.photo).report
    assert report.engine_dimensions == cloud.dimensions
    assert report.points == cloud.points and report.faces == cloud.faces
    assert report.warnings == [*done.measured.warnings, *cloud.warnings]


def test_a_station_report_stands_when_the_cloud_is_refused(on_station, monkeypatch, schema):
    sc, station = on_station

    def refuse(*args: object, **kwargs: object) -> None:
        raise InputError("P3 is not where it should be")

    monkeypatch.setattr(station_scan, "run_scan", refuse)
    done = scan_on_station(sc.photo, station, "part.jpg", {"formats": ["csv"]})
    assert done.result is None
    content = json.loads(report_bytes(done.report))
    assert set(content) == REFUSED
    assert content["engine_dimensions"] is None
    said = "no cloud: the derived points were refused (P3 is not where it should be)"
    assert content["warnings"][-1] == said
    assert set(content["timings_ms"]) == {"station"}
    jsonschema.Draft202012Validator(schema).validate(content)


def test_a_report_keeps_to_its_model():
    content = {"dimensions": {"width": 1, "height": 2, "depth": 3, "unit": "mm"}, "warnings": [],
               "timings_ms": {}}
    assert report_dict(ScanReport.model_validate(content)) == content  # absent stays absent
    with pytest.raises(ValueError, match="unknown"):
        ScanReport.model_validate({**content, "unknown": 1})
    with pytest.raises(ValueError, match="unit"):
        ScanReport.model_validate({**content, "dimensions": {**content["dimensions"], "unit": "in"}})

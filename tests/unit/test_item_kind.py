"""`ScanSpec.kind` and the tables that dispatch on it (issue 35): for any valid spec, the worker,
`prism scan` and the API pick what they picked when each worked the kind out of the spec's
fields itself, in its own order (the tests below keep those orders as they were)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from prism_api import validation
from prism_cli import scan_runners
from prism_worker import tasks
from prismcore import ScanSpec
from prismcore.spec_fields import ITEM_KINDS

Doc = dict[str, Any]

SEVEN = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8], [12, 78], [198, 74]]
FIVE = SEVEN[:5]
VIEWS = [{"image": "a.png", "points": SEVEN}, {"image": "b.png", "points": SEVEN}]
EDGE = {"kind": "edge", "edge": "width", "length_mm": 100.0}

SPECS: dict[str, dict[str, Any]] = {
    "photo": {"image": "a.png", "points": FIVE},
    "found": {"image": "a.png", "points": "auto"},
    "video": {"image": "clip.mp4", "points": FIVE, "frames": {}},
    "tracked": {"image": "clip.mp4", "points": SEVEN, "frames": {}, "points_frame": 0},
    "tracked_joint": {"image": "clip.mp4", "points": SEVEN, "frames": {}, "points_frame": 0,
                      "fit": "joint", "scale": EDGE},
    "frames_joint": {"image": "clip.mp4", "frame_points": {"0": SEVEN, "3": SEVEN}, "fit": "joint",
                     "scale": EDGE},
    "views": {"views": VIEWS, "scale": EDGE},
    "station": {"image": "a.png", "station": "0" * 32},
}
"""A spec of each kind, named by it."""


# The fields that tell a kind, each one of a few values.
FIELDS = {
    "image": st.sampled_from(["a.png", "clip.mp4"]),
    "points": st.sampled_from([SEVEN, FIVE, "auto"]),
    "auto_points": st.sampled_from([{}, {"hint": [50, 40]}]),
    "side_image": st.just("b.png"),
    "frames": st.sampled_from([{}, {"every": 2}, {"indices": [0, 3]}]),
    "frame_points": st.sampled_from([{"0": SEVEN, "3": SEVEN}, {"0": FIVE}]),
    "points_frame": st.just(0),
    "views": st.just(VIEWS),
    "fit": st.sampled_from(["joint", "frames"]),
    "station": st.just("0" * 32),
    "scale": st.sampled_from([EDGE, {"kind": "mm_per_px", "front": 0.5}]),
}


def _spec(doc: dict[str, Any]) -> ScanSpec:
    try:
        return ScanSpec.model_validate(doc)
    except ValidationError:
        assume(False)
        raise  # not reached: assume(False) ends the example


# The orders each caller tested the fields in before the kind was named (issue 35).
def _worker_before(spec: ScanSpec) -> str:
    if spec.views is not None or spec.fit == "joint":
        return "joint"
    if spec.station is not None:
        return "station"
    return "video" if spec.is_video else "photo"


def _cli_before(spec: ScanSpec) -> str:
    if spec.station is not None:
        return "station"
    if spec.points_frame is not None:
        return "tracked"
    if spec.views is not None or spec.fit == "joint":
        return "views" if spec.views is not None else "frames_joint"
    return "video" if spec.is_video else "photo"


def _api_before(spec: ScanSpec) -> tuple[str, bool]:
    joint = spec.views is not None or spec.fit == "joint"
    return ("views" if spec.views is not None else "station" if spec.station is not None
            else "points"), joint


_WORKER = {tasks._plan_joint: "joint", tasks._plan_station: "station", tasks._split_video: "video",
           tasks._plan_photo: "photo"}
_CLI = {scan_runners.run_station: "station", scan_runners.run_tracked: "tracked",
        scan_runners.run_views: "views", scan_runners.run_frames_joint: "frames_joint",
        scan_runners.run_video: "video", scan_runners.run_photo: "photo"}
_API = {validation._check_views_item: "views", validation._check_station_item: "station",
        validation._check_points: "points"}


# A spec of each kind, and up to two fields drawn over it: most draws are specs of some kind
# (often another one), the rest are refused by the spec's rules and drawn again.
drawn = st.tuples(
    st.sampled_from(sorted(SPECS.items())),
    st.lists(st.sampled_from(sorted(FIELDS)), max_size=2, unique=True).flatmap(
        lambda names: st.fixed_dictionaries({n: FIELDS[n] for n in names})))


@settings(max_examples=300, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow])
@given(doc=drawn)
def test_every_table_picks_what_its_caller_picked_before(doc: tuple[tuple[str, Doc], Doc]) -> None:
    (_, base), extra = doc
    spec = _spec({**base, **extra})
    event(spec.kind)
    assert _WORKER[tasks.PLANS[spec.kind]] == _worker_before(spec)
    assert _CLI[scan_runners.RUNNERS[spec.kind]] == _cli_before(spec)
    api = validation.KINDS[spec.kind]
    assert (_API[api.check], api.own_formats) == _api_before(spec)


def test_every_table_names_every_kind() -> None:
    for table in (tasks.PLANS, scan_runners.RUNNERS, validation.KINDS):
        assert sorted(table) == sorted(ITEM_KINDS)


ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "explanation" / "architecture.md"


def test_the_architecture_page_draws_the_kind_table() -> None:
    """The page's table of kinds has a row for each kind, and the `prism scan` runner it names is
    the one `RUNNERS` picks (a kind prism scan refuses names none)."""
    section = ARCHITECTURE.read_text(encoding="utf-8").split("## The item's kind", 1)[1].split("\n## ", 1)[0]
    tables = ("tasks.PLANS", "scan_runners.RUNNERS", "validation.KINDS", "prismcore.spec_fields.item_kind")
    for table in tables:
        assert f"`{table}`" in section, table
    rows = [[cell.strip() for cell in line.strip("|").split("|")]
            for line in section.splitlines() if re.match(r"\| `\w+` \|", line)]
    assert [row[0].strip("`") for row in rows] == list(ITEM_KINDS)
    for row in rows:
        named = re.findall(r"`(run_\w+)`", row[3])
        runner = scan_runners.RUNNERS[row[0].strip("`")].__name__  # type: ignore[index]
        assert named == [runner] or (not named and row[3].startswith("refused")), row


def test_each_kind_is_met() -> None:
    assert {kind: ScanSpec.model_validate(doc).kind for kind, doc in SPECS.items()} == \
        {kind: kind for kind in ITEM_KINDS}

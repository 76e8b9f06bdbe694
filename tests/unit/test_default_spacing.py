"""The cloud spacing an item gets at submit (`prism_api.routes.jobs._spacing`): its own always
(an explicit null: one point per pixel); else the operator's PRISM_DEFAULT_SPACING_MM (unset:
1 mm) for an item in mm (a scale, or a station's plane); none for an item in pixels or a
joint fit (no cloud). The stored spec, validated again as the worker reads it, keeps it.

The oracle is the rule written out over every combination, not the function's own code.
"""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from prism_common.settings import Settings

from prism_api.routes.jobs import _spacing
from prismcore import ScanSpec

SEVEN = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8], [12, 78], [198, 74]]
EDGE = {"kind": "edge", "edge": "width", "length_mm": 100.0}
SPECS: dict[str, dict[str, Any]] = {  # a spec of each kind (as tests/unit/test_item_kind.py's)
    "photo": {"image": "a.png", "points": SEVEN[:5]},
    "found": {"image": "a.png", "points": "auto"},
    "video": {"image": "clip.mp4", "points": SEVEN[:5], "frames": {}},
    "tracked": {"image": "clip.mp4", "points": SEVEN, "frames": {}, "points_frame": 0},
    "tracked_joint": {"image": "clip.mp4", "points": SEVEN, "frames": {}, "points_frame": 0,
                      "fit": "joint", "scale": EDGE},
    "frames_joint": {"image": "clip.mp4", "frame_points": {"0": SEVEN, "3": SEVEN}, "fit": "joint",
                     "scale": EDGE},
    "views": {"views": [{"image": "a.png", "points": SEVEN}, {"image": "b.png", "points": SEVEN}],
              "scale": EDGE},
    "station": {"image": "a.png", "station": "0" * 32},
}
SCALE = {"kind": "mm_per_px", "front": 0.5}
SCALED = {"photo", "found", "video", "tracked", "station"}  # kinds that may take a scale or have one


def _settings(**env: Any) -> Settings:
    return Settings(api_keys={"t": "k" * 16}, webhook_secret="x" * 16, **env)


def test_the_service_default_is_a_millimetre(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PRISM_DEFAULT_SPACING_MM", raising=False)
    assert _settings().default_spacing_mm == 1.0


@pytest.mark.parametrize("value", ["null", "", "None"])
def test_the_operator_asks_for_one_point_per_pixel(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv("PRISM_DEFAULT_SPACING_MM", value)
    assert _settings().default_spacing_mm is None


def test_the_operator_sets_the_spacing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PRISM_DEFAULT_SPACING_MM", "1.5")
    assert _settings().default_spacing_mm == 1.5
    monkeypatch.setenv("PRISM_DEFAULT_SPACING_MM", "0")
    with pytest.raises(ValueError, match="greater than 0"):
        _settings()


OWN: list[Any] = ["unset", None, 2.0]


@pytest.mark.parametrize(("kind", "default", "own", "scaled"),
                         list(itertools.product(sorted(SPECS), [0.5, None], OWN, [True, False])))
def test_an_items_spacing(kind: str, default: float | None, own: Any, scaled: bool) -> None:
    doc = dict(SPECS[kind])
    joint = kind in ("tracked_joint", "frames_joint", "views")
    in_mm = kind == "station" or joint or scaled
    if scaled and kind in SCALED - {"station"}:
        doc["scale"] = SCALE
    if own != "unset":
        doc["spacing_mm"] = own
    try:
        spec = ScanSpec.model_validate(doc)
    except ValueError:  # the spec itself refuses a spacing without a scale, or with a joint fit
        assert own == 2.0 and (joint or not in_mm)
        return
    got = _spacing(spec, default)
    if own != "unset":
        want = own
    elif joint or not in_mm or (kind != "station" and "scale" not in doc):
        want = None
    else:
        want = default
    assert got == want
    # what the worker reads back: the stored spec with the spacing, validated again
    stored = spec.model_copy(update={"spacing_mm": got})
    assert ScanSpec.model_validate(stored.model_dump(mode="json")).spacing_mm == got

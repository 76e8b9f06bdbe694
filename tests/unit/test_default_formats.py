"""The formats an item gets at submit (`prism_api.routes.jobs._formats`): its own list always;
else the operator's PRISM_DEFAULT_FORMATS (unset: csv + ply, as the design promises), less the
metric ones (las, laz, glb, step, drawing: in mm) for an item without a scale; csv + ply when nothing is left.

The oracle is the rule written out over every combination, not the function's own code.
"""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from prism_common.settings import Settings

from prism_api.routes.jobs import _formats
from prismcore import ScanSpec

POINTS = [[10, 10], [110, 12], [108, 80], [150, 6], [200, 8]]
METRIC = {"las", "laz", "glb", "step", "drawing"}
SCALE = {"kind": "mm_per_px", "front": 0.5}


def _settings(**env: Any) -> Settings:
    return Settings(api_keys={"t": "k" * 16}, webhook_secret="x" * 16, **env)


def test_the_service_default_is_csv_and_ply(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PRISM_DEFAULT_FORMATS", raising=False)
    assert _settings().default_formats == ["csv", "ply"]


def test_the_operator_sets_the_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PRISM_DEFAULT_FORMATS", '["laz", "glb"]')  # the compact ones
    assert _settings().default_formats == ["laz", "glb"]


DEFAULTS = [["laz", "glb"], ["csv", "ply"], ["las"], ["glb", "csv"], ["ply"], ["step", "drawing", "csv"]]
OWN = [None, ["csv"], ["ply", "csv"], ["laz"], ["glb", "las", "ply"], ["drawing", "step"]]


@pytest.mark.parametrize(("defaults", "own", "scaled"), list(itertools.product(DEFAULTS, OWN, [True, False])))
def test_an_items_formats(defaults: list[str], own: list[str] | None, scaled: bool) -> None:
    doc: dict[str, Any] = {"image": "upload:" + "0" * 32, "points": POINTS}
    if scaled:
        doc["scale"] = SCALE
    if own is not None:
        if not scaled and METRIC & set(own):
            with pytest.raises(ValueError, match="scale"):  # the spec itself refuses it
                ScanSpec.model_validate({**doc, "formats": own})
            return
        doc["formats"] = own
    got = _formats(ScanSpec.model_validate(doc), defaults)  # type: ignore[arg-type]
    if own is not None:
        want = own
    elif scaled:
        want = defaults
    else:
        want = [f for f in defaults if f not in METRIC] or ["csv", "ply"]
    assert got == want
    if not scaled:
        assert not METRIC & set(got)  # what an item without a scale gets, it can have

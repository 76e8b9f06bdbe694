"""A spec's validation error as the CLI prints it: one line, the field named once, none of
pydantic's own wording ("Value error, ")."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from prism_cli.scan_flags import one_line
from prismcore import ScanSpec

VIEW = {"points": [[1.0, 1.0]] * 7}
EDGE = {"kind": "edge", "edge": "width", "length_mm": 10.0}


@pytest.mark.parametrize(("spec", "line"), [
    ({"views": []}, "views: a joint fit needs at least 2 views of the part, got 0"),
    ({"views": [{"image": "a.jpg", **VIEW}, {"image": "b.jpg", **VIEW}], "tolerance": 20, "scale": EDGE},
     "tolerance does not go with views: "),
    ({"image": "a.jpg", "points": [[1, 2]]}, "points: give 5 or 7 points, got 1"),
])
def test_the_field_is_named_once(spec: dict, line: str):
    with pytest.raises(ValidationError) as caught:
        ScanSpec.model_validate(spec)
    printed = one_line(caught.value)
    assert printed.startswith(line), printed
    assert "Value error" not in printed and "\n" not in printed
    field = line.split(":")[0].split(" ")[0]
    assert printed.count(f"{field}:") + printed.count(f"{field} does") == 1, printed

"""A joint item's views are held decoded together: the worker stops at JOINT_MAX_PIXELS (the API
refuses what it knows of the uploads' sizes at submit; a URL's size is known only here)."""

from __future__ import annotations

import pytest

from prism_worker.joint_item import _within_budget
from prismcore import InputError
from prismcore.spec import JOINT_MAX_PIXELS


@pytest.mark.parametrize("pixels", [1, 12_000_000, JOINT_MAX_PIXELS])
def test_views_up_to_the_budget_are_held(pixels: int) -> None:
    assert _within_budget(JOINT_MAX_PIXELS - pixels, pixels, "views.3 (d.jpg)") == JOINT_MAX_PIXELS


def test_the_view_past_the_budget_is_named_with_the_total() -> None:
    with pytest.raises(InputError, match=r"^views\.12 \(m\.jpg\) brings the views to 156 megapixels "
                                         r"together, over a joint fit's 150"):
        _within_budget(12 * 12_000_000, 12_000_000, "views.12 (m.jpg)")

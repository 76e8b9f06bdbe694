"""The video summary against numpy on the per-frame values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from prismcore.video.summary import DIMENSIONS, summarize

sizes = st.floats(1.0, 1000.0, allow_nan=False)


def _report(width: float, height: float, depth: float, unit: str = "mm") -> dict:
    return {"dimensions": {"width": width, "height": height, "depth": depth, "unit": unit}}


@given(rows=st.lists(st.tuples(sizes, sizes, sizes), min_size=2, max_size=40),
       failed=st.sets(st.integers(1000, 1100), max_size=5))
def test_statistics_match_numpy(rows, failed):
    per_frame = {3 * i: _report(*row) for i, row in enumerate(rows)}
    per_frame.update({i: {"error": f"bad frame {i}"} for i in failed})
    summary = summarize(per_frame)
    assert summary["frames"] == {"selected": len(rows) + len(failed), "measured": len(rows),
                                 "failed": len(failed)}
    assert summary["unit"] == "mm"
    values = np.array(rows)
    for k, name in enumerate(DIMENSIONS):
        col, got = values[:, k], summary["dimensions"][name]
        expected = {"median": np.median(col), "min": col.min(), "max": col.max(),
                    "spread": np.ptp(col), "std": np.std(col, ddof=1),
                    "relative_spread": np.ptp(col) / np.median(col)}
        for key, value in expected.items():
            assert got[key] == pytest.approx(value, rel=1e-6, abs=1e-6), (name, key)
    assert [r["frame"] for r in summary["per_frame"]] == [3 * i for i in range(len(rows))]
    assert summary["failed"] == [{"frame": i, "error": f"bad frame {i}"} for i in sorted(failed)]


def test_one_frame_has_no_std_and_times_follow_the_rate():
    summary = summarize({50: _report(120.0, 80.0, 60.0)}, fps=25.0)
    assert summary["dimensions"]["width"] == {"median": 120.0, "min": 120.0, "max": 120.0,
                                              "spread": 0.0, "std": None, "relative_spread": 0.0}
    assert summary["per_frame"] == [{"frame": 50, "time_s": 2.0, "width": 120.0, "height": 80.0,
                                     "depth": 60.0}]


def test_no_frame_measured():
    summary = summarize({0: {"error": "x"}, 1: {"error": "y"}})
    assert summary["dimensions"] == {} and summary["unit"] is None and summary["per_frame"] == []
    assert summary["frames"] == {"selected": 2, "measured": 0, "failed": 2}


def test_inconsistent_reports_are_refused():
    with pytest.raises(ValueError, match=r"different units: \['mm', 'px'\]"):
        summarize({0: _report(1, 2, 3, "mm"), 1: _report(1, 2, 3, "px")})
    with pytest.raises(ValueError, match="frame 4: the report has no dimensions and no error"):
        summarize({4: {"points": 10}})


def test_summary_json_adds_the_video_the_selection_the_focal_and_extra_blocks_in_order():
    from prismcore.scan.focal import PooledFocal
    from prismcore.spec import FrameSelection
    from prismcore.video.summary import video_summary

    per_frame = {0: _report(10, 20, 30), 10: _report(11, 21, 31), 20: {"error": "no box"}}
    summary = video_summary(per_frame, fps=10.0, video={"path": "v.mp4", "fps": 10.0},
                            selection=FrameSelection(every=10), pooled=PooledFocal(1400.04, 2.0004, (0, 1)),
                            pooled_frames=[0, 10], extra={"tracking": {"frame": 0}})
    assert summary == {**summarize(per_frame, fps=10.0), "video": {"path": "v.mp4", "fps": 10.0},
                       "selection": {"every": 10},
                       "focal": {"pooled_px": 1400.04, "std_px": 2.0, "frames": [0, 10]},
                       "tracking": {"frame": 0}}
    assert list(summary)[-4:] == ["video", "selection", "focal", "tracking"]
    plain = video_summary(per_frame, fps=None, video={}, selection=FrameSelection(every=10))
    assert "focal" not in plain and list(plain)[-2:] == ["video", "selection"]

"""Zero-click on a real video: the point search on the hand-marked frames of OpenCV's cookie-box
video (issue 12's real-video acceptance: points within 5 px of the hand marks on at least 80 % of
the marked frames, median dimensions within 3 % with no clicks and one known edge).

Run: .venv/bin/python benchmarks/zero_click_real_video.py
For each marked right-side frame (benchmarks/data/opencv_box_marks.json): `find_points` with no
hint, the largest distance from a found point to its hand mark, and, when found, the frame
measured from the found points with the front's width as the known edge and no focal length.
Needs Debian's opencv-doc package (real_video_data installs the video when missing).
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from prismcore import InputError, ScanSpec, run_scan
from prismcore.locate.search import find_points, resolve_points

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_video_data import load_marks, points_of, read_frames, truth_mm, video_path

NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def main() -> None:
    marked = [f for f in load_marks()["frames"] if f["side"] == "right"]
    frames = read_frames(video_path(), [f["index"] for f in marked])
    table = Table(title="Zero-click on the real cookie-box video (no hint, width known, no focal)")
    for name in ("frame", "found", "confidence", "worst px to mark", "H err %", "D err %", "reason"):
        table.add_column(name)
    close, errors = 0, {"height": [], "depth": []}
    for frame in marked:
        image, truth = frames[frame["index"]], truth_mm(frame)
        found = find_points(image)
        if not found.ok or found.points is None:
            table.add_row(str(frame["index"]), "no", "-", "-", "-", "-", found.reason or "")
            continue
        got = found.points.as_dict()
        worst = max(float(np.hypot(got[n][0] - x, got[n][1] - y))
                    for n, (x, y) in zip(NAMES, points_of(frame), strict=False) if got.get(n) is not None)
        close += worst <= 5.0
        spec = ScanSpec.model_validate({"image": "frame.png", "points": "auto", "formats": ["csv"],
                                        "scale": {"kind": "edge", "edge": "width",
                                                  "length_mm": truth["width"]}})
        try:
            resolved, _ = resolve_points(spec, image)
            dims = run_scan(resolved, image).report.dimensions.model_dump()
        except InputError as exc:
            table.add_row(str(frame["index"]), "yes", f"{found.confidence:.2f}", f"{worst:.1f}", "-", "-",
                          str(exc))
            continue
        err = {a: 100 * (dims[a] / truth[a] - 1) for a in ("height", "depth")}
        for a, e in err.items():
            errors[a].append(abs(e))
        table.add_row(str(frame["index"]), "yes", f"{found.confidence:.2f}", f"{worst:.1f}",
                      f"{err['height']:+.1f}", f"{err['depth']:+.1f}", "")
    console = Console()
    console.print(table)
    medians = ", ".join(f"{a} {statistics.median(v):.1f} %" for a, v in errors.items() if v)
    console.print(f"found within 5 px of the marks: {close} of {len(marked)} frames "
                  f"(target 80 %); median |error|: {medians or 'none measured'} (target 3 %)")


if __name__ == "__main__":
    main()

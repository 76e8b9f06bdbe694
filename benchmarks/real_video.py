"""Real video: the hand-marked frames of OpenCV's cookie-box video, measured with one known edge.

Run: .venv/bin/python benchmarks/real_video.py [--frames 127,141] [--json out.json]
For each marked frame (benchmarks/data/opencv_box_marks.json) the engine measures the photo with
the front's width as the known edge and no focal length (fitted from the box when the engine can),
then again with the tutorial's published camera intrinsics as a baseline. Prints measured
height and depth against the truth (258 x 189 x 75 mm), their % errors, the report's camera and
uncertainty fields when present, and the median over frames. Needs Debian's opencv-doc package.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_video_data import (
    TUTORIAL_CAMERA,
    load_marks,
    points_of,
    read_frames,
    truth_mm,
    video_path,
)

from prismcore import InputError, ScanSpec, run_scan


def measure(frame: dict, image: np.ndarray, camera: dict | None = None) -> dict:
    """One marked frame through the engine: width known, no focal length unless `camera`.

    Returns the row of figures: measured and true mm, % errors (None when the engine refused,
    with its message in ``error``), and the report's camera and uncertainty when present.
    """
    truth = truth_mm(frame)
    spec: dict = {"image": f"frame_{frame['index']}.png", "points": points_of(frame),
                  "scale": {"kind": "edge", "edge": "width", "length_mm": truth["width"]},
                  "formats": ["csv"]}
    if camera is not None:
        spec["camera"] = camera
    row: dict = {"frame": frame["index"], "truth": truth}
    try:
        report = run_scan(ScanSpec.model_validate(spec), image).report
    except InputError as exc:
        return {**row, "error": str(exc), "errors_pct": None}
    dims = report["dimensions"]
    row["measured"] = {a: dims[a] for a in ("width", "height", "depth")}
    row["errors_pct"] = {a: 100 * (dims[a] / truth[a] - 1) for a in ("height", "depth")}
    row["camera"] = report.get("camera")
    row["uncertainty"] = report.get("uncertainty")
    row["warnings"] = report.get("warnings", [])
    return row


def median_abs(rows: list[dict], axis: str) -> float | None:
    values = [abs(r["errors_pct"][axis]) for r in rows if r["errors_pct"] is not None]
    return statistics.median(values) if values else None


def _table(title: str, rows: list[dict]) -> Table:
    table = Table(title=title)
    for col in ("frame", "W mm", "H mm", "D mm", "truth WxHxD", "H err %", "D err %", "focal px (source)",
                "sigma H/D mm", "note"):
        table.add_column(col, justify="right" if col != "note" else "left")
    for r in rows:
        t = r["truth"]
        truth = f"{t['width']:.0f}x{t['height']:.0f}x{t['depth']:.0f}"
        if r["errors_pct"] is None:
            table.add_row(str(r["frame"]), "-", "-", "-", truth, "-", "-", "-", "-", r["error"][:40])
            continue
        m, e, cam, unc = r["measured"], r["errors_pct"], r.get("camera") or {}, r.get("uncertainty") or {}
        focal = f"{cam['focal_px']:.0f} ({cam.get('focal_source', '?')})" if cam.get("focal_px") else "-"
        sigma = f"{unc['height']:.1f}/{unc['depth']:.1f}" if "height" in unc and "depth" in unc else "-"
        table.add_row(str(r["frame"]), f"{m['width']:.1f}", f"{m['height']:.1f}", f"{m['depth']:.1f}", truth,
                      f"{e['height']:+.1f}", f"{e['depth']:+.1f}", focal, sigma,
                      f"{len(r['warnings'])} warning(s)" if r["warnings"] else "")
    h, d = median_abs(rows, "height"), median_abs(rows, "depth")
    failed = sum(r["errors_pct"] is None for r in rows)
    median = f"median |error|: height {h:.1f} %, depth {d:.1f} %" if h is not None and d is not None \
        else "no frame measured"
    table.caption = median + (f"; {failed} frame(s) refused" if failed else "")
    return table


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", help="comma-separated frame indices (default: every marked frame)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)
    marks = load_marks()
    frames = marks["frames"]
    if args.frames:
        wanted = {int(f) for f in args.frames.split(",")}
        unknown = wanted - {f["index"] for f in frames}
        if unknown:
            parser.error(f"frames {sorted(unknown)} are not marked")
        frames = [f for f in frames if f["index"] in wanted]
    frames = [f for f in frames if f["side"] == "right"]  # the engine's single-photo mode today
    images = read_frames(video_path(), [f["index"] for f in frames])
    runs = {"no focal (fitted)": [measure(f, images[f["index"]]) for f in frames],
            "tutorial camera (fx 1578, fy 1772)": [measure(f, images[f["index"]], TUTORIAL_CAMERA)
                                                   for f in frames]}
    console = Console(width=170)
    for title, rows in runs.items():
        console.print(_table(title, rows))
    if args.json:
        args.json.write_text(json.dumps(runs, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

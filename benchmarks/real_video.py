"""Real video: the hand-marked frames of OpenCV's cookie-box video, measured with one known edge.

Run: .venv/bin/python benchmarks/real_video.py [--frames 127,141] [--pooled] [--focal 560,620]
     [--clicks-only] [--json out.json]
For each marked frame (benchmarks/data/opencv_box_marks.json) the engine measures the photo with
the front's width as the known edge and no focal length (fitted from the box), one table for the
frames whose second face is the lid (``side: top``, spec ``side_face: top``) and one for those with
the right end wall (``side: right``), then again with the tutorial's published camera intrinsics
as a baseline. With --pooled, every frame's fitted focal length (plan only) is pooled with
``prismcore.video.pooling.pool_focal`` and every frame is measured again with that focal length given;
with --focal, again with each of those focal lengths given (is any one focal length right for the
video?). With --clicks-only, every run takes the clicked sides as the edges (no edge refinement):
what the refinement adds or costs on this box.
Prints measured height and depth against the truth (258 x 189 x 75 mm), their % errors, the report's camera
and uncertainty fields when present, and the median over frames. Needs Debian's opencv-doc package.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import sys
from collections.abc import Iterator
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

import prismcore.scan.pipeline
from prismcore import InputError, ScanSpec, plan_scan, run_scan
from prismcore.geometry.edges import EdgeFit, line_through
from prismcore.geometry.faces import FaceQuads
from prismcore.report import report_dict
from prismcore.video.pooling import pool_focal


@contextlib.contextmanager
def clicks_as_edges() -> Iterator[None]:
    """Within the block the engine takes each clicked side as its edge (no refinement), as its
    snap guard does when it rejects the refined edges."""
    def unrefined(spec: ScanSpec, images: list[np.ndarray], clicked: FaceQuads, warnings: list[str]
                  ) -> tuple[FaceQuads, dict[str, list[EdgeFit]]]:
        fits = {n: [EdgeFit(line_through(q[i], q[(i + 1) % 4]), 0.0, 0.0, False) for i in range(4)]
                for n, q in (("front", clicked.front), ("side", clicked.side))}
        return clicked, fits

    saved = prismcore.scan.pipeline.refine_faces
    prismcore.scan.pipeline.refine_faces = unrefined
    try:
        yield
    finally:
        prismcore.scan.pipeline.refine_faces = saved


def frame_spec(frame: dict, camera: dict | None = None, focal_px: float | None = None) -> ScanSpec:
    """The engine spec of one marked frame: width known, its second face named by ``side``."""
    spec: dict = {"image": f"frame_{frame['index']}.png", "points": points_of(frame),
                  "side_face": frame["side"],
                  "scale": {"kind": "edge", "edge": "width", "length_mm": truth_mm(frame)["width"]},
                  "formats": ["csv"]}
    if camera is not None:
        spec["camera"] = camera
    if focal_px is not None:
        spec["focal_px"] = focal_px
    return ScanSpec.model_validate(spec)


def fitted_focal(frame: dict, image: np.ndarray) -> tuple[float, float] | None:
    """The frame's own focal fit (plan only): (focal_px, focal_std_px), or None when refused."""
    try:
        cam = plan_scan(frame_spec(frame), image).camera
    except InputError:
        return None
    if cam.get("focal_source") != "fitted":
        return None
    return float(cam["focal_px"]), float(cam["focal_std_px"])


def measure(frame: dict, image: np.ndarray, camera: dict | None = None,
            focal_px: float | None = None) -> dict:
    """One marked frame through the engine: width known, no focal length unless `camera` or
    `focal_px`.

    Returns the row of figures: measured and true mm, % errors (None when the engine refused,
    with its message in ``error``), and the report's camera and uncertainty when present.
    """
    truth = truth_mm(frame)
    row: dict = {"frame": frame["index"], "side": frame["side"], "truth": truth}
    try:
        report = report_dict(run_scan(frame_spec(frame, camera, focal_px), image).report)
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
                "focal std", "sigma H/D mm", "note"):
        table.add_column(col, justify="right" if col != "note" else "left")
    for r in rows:
        t = r["truth"]
        truth = f"{t['width']:.0f}x{t['height']:.0f}x{t['depth']:.0f}"
        if r["errors_pct"] is None:
            table.add_row(str(r["frame"]), "-", "-", "-", truth, "-", "-", "-", "-", "-", r["error"][:40])
            continue
        m, e, cam, unc = r["measured"], r["errors_pct"], r.get("camera") or {}, r.get("uncertainty") or {}
        focal = f"{cam['focal_px']:.0f} ({cam.get('focal_source', '?')})" if cam.get("focal_px") else "-"
        std = f"{cam['focal_std_px']:.0f}" if cam.get("focal_std_px") else "-"
        sigma = f"{unc['height']:.1f}/{unc['depth']:.1f}" if "height" in unc and "depth" in unc else "-"
        table.add_row(str(r["frame"]), f"{m['width']:.1f}", f"{m['height']:.1f}", f"{m['depth']:.1f}", truth,
                      f"{e['height']:+.1f}", f"{e['depth']:+.1f}", focal, std, sigma,
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
    parser.add_argument("--pooled", action="store_true",
                        help="also measure every frame with the focal length pooled over the frames' fits")
    parser.add_argument("--focal", help="comma-separated focal lengths (px): also measure with each given")
    parser.add_argument("--clicks-only", action="store_true",
                        help="take the clicked sides as the edges (no edge refinement)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)
    focals = [float(f) for f in args.focal.split(",")] if args.focal else []
    marks = load_marks()
    frames = marks["frames"]
    if args.frames:
        wanted = {int(f) for f in args.frames.split(",")}
        unknown = wanted - {f["index"] for f in frames}
        if unknown:
            parser.error(f"frames {sorted(unknown)} are not marked")
        frames = [f for f in frames if f["index"] in wanted]
    images = read_frames(video_path(), [f["index"] for f in frames])
    with clicks_as_edges() if args.clicks_only else contextlib.nullcontext():
        runs, pooled_info = _runs(frames, images, args.pooled, focals)
    console = Console(width=190)
    for title, rows in runs.items():
        console.print(_table(title + (" [clicks only]" if args.clicks_only else ""), rows))
    if args.json:
        figures = {"runs": runs, "pooled": pooled_info}
        args.json.write_text(json.dumps(figures, indent=1, default=float) + "\n")
    return 0


def _runs(frames: list[dict], images: dict[int, np.ndarray], pooled: bool, focals: list[float]
          ) -> tuple[dict[str, list[dict]], dict[str, dict]]:
    """Every table's rows, by title, and the pooled focal length's details per side."""
    runs: dict[str, list[dict]] = {}
    pooled_info: dict[str, dict] = {}
    for side in ("top", "right"):
        group = [f for f in frames if f["side"] == side]
        if not group:
            continue
        runs[f"{side}: no focal (fitted)"] = [measure(f, images[f["index"]]) for f in group]
        if pooled:
            fits = [fitted_focal(f, images[f["index"]]) for f in group]
            usable = [(f, fit) for f, fit in zip(group, fits, strict=True) if fit is not None]
            found = pool_focal([fit for _, fit in usable])
            if found is not None:
                pooled_info[side] = {"focal_px": found.focal_px, "std_px": found.std_px,
                                     "used": [usable[k][0]["index"] for k in found.used],
                                     "fits": {f["index"]: fit for f, fit in usable}}
                runs[f"{side}: pooled focal {found.focal_px:.0f} +- {found.std_px:.0f} px "
                     f"({len(found.used)}/{len(group)} fits)"] = [
                    measure(f, images[f["index"]], focal_px=found.focal_px) for f in group]
        for focal in focals:
            runs[f"{side}: focal {focal:g} px given"] = [
                measure(f, images[f["index"]], focal_px=focal) for f in group]
        runs[f"{side}: tutorial camera (fx 1578, fy 1772)"] = [
            measure(f, images[f["index"]], TUTORIAL_CAMERA) for f in group]
    return runs, pooled_info


if __name__ == "__main__":
    raise SystemExit(main())

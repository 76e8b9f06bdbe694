"""`prism scan PHOTO --points ...`: one photo (or a front and a side photo) measured, its points
clicked or found in it (points "auto"), its outputs written to one folder and summed up in a few
lines."""

from __future__ import annotations

import time
from pathlib import Path

from prismcore.io import EXIF_HEAD_BYTES, exif_focal, load_image
from prismcore.locate import scan_found
from prismcore.outputs import given_dimension, points_found
from prismcore.report import Quality, ScanReport
from prismcore.spec import ScanSpec

from .console import rich_console as console
from .outputs import write_report, write_scan

__all__ = ["quality_lines", "scan_photo", "summary_line"]


def scan_photo(spec: ScanSpec, base: Path, out: Path, *, tiles: int, overlay_format: str,
               started: float) -> None:
    """Measure the photo of `spec` (paths relative to `base`), write its outputs to `out` and print
    the summary, the quality verdicts, the warnings and the files written."""
    load_start = time.perf_counter()
    front = load_image(base / spec.image, max_pixels=spec.max_pixels)
    side_img = (load_image(base / spec.side_image, max_pixels=spec.max_pixels)
                if spec.side_image else None)
    found = exif_focal(_head(base / spec.image), front.shape[1], front.shape[0])
    load_ms = (time.perf_counter() - load_start) * 1000
    auto = None
    if spec.auto_points is not None:
        # imported for points "auto" only: a photo with its points clicked loads no search
        from prismcore.locate import resolve_points

        spec, auto = resolve_points(spec, front)
    result = scan_found(spec, auto.report() if auto else None, front, side_img, tiles=tiles,
                        exif_focal_px=found.focal_px if found else None)
    result.report.timings_ms["load"] = round(load_ms, 3)
    paths = write_scan(result, spec, out, [front] + ([side_img] if side_img is not None else []),
                       overlay_format)
    result.report.timings_ms["total"] = round((time.perf_counter() - started) * 1000, 3)
    paths["report"] = write_report(result.report, out)
    console().print(summary_line(result.report), soft_wrap=True)
    for line in quality_lines(result.report.quality):
        console().print(line, soft_wrap=True)
    for warning in result.report.warnings:
        console().print(f"[yellow]warning:[/] {warning}", soft_wrap=True)
    wide = max(map(len, paths))
    for kind, path in paths.items():
        console().print(f"{kind:>{wide}}: {path}", soft_wrap=True)  # a path must stay one line to be copied


def _head(path: Path) -> bytes:
    with path.open("rb") as fh:
        return fh.read(EXIF_HEAD_BYTES)


def summary_line(report: ScanReport) -> str:
    """'640,268 points  120.00 ± 0.14 x 79.99 ± 0.09 x 59.99 ± 0.51 mm  focal 1400 px (fitted)
    point loss 0.1%'; a known edge's dimension as '120.00 (given)'; points the search found
    as '  points found (confidence 0.99)' at the end."""
    dims, sigma = report.dimensions, report.uncertainty
    given = given_dimension(report)
    sizes = " x ".join(f"{getattr(dims, k):.2f}" + (" (given)" if k == given else
                                                    "" if sigma is None else f" ± {getattr(sigma, k):.2f}")
                       for k in ("width", "height", "depth"))
    camera = report.camera
    focal = (f"  focal {camera.focal_px:.0f} px ({camera.focal_source})"
             if camera is not None and camera.focal_px else "")
    found = points_found(report)
    return (f"[bold]{report.points or 0:,} points[/]  {sizes} {dims.unit}{focal}"
            f"  point loss {report.point_loss or 0.0:.1%}" + (f"  {found}" if found else ""))


_VERDICT_STYLE = {"pass": "green", "fail": "red", "uncertain": "yellow"}


def quality_lines(quality: Quality | None) -> list[str]:
    """One line per dimension and the part's verdict (rich markup), or none without a nominal:
    'width   120.05 mm  nominal 120.00 ± 0.10  deviation +0.05 (± 0.04 at k=2)  pass'."""
    if quality is None:
        return []
    lines = []
    for name, row in quality.dimensions.items():
        sigma = "" if row.sigma_mm is None else f" (± {quality.k * row.sigma_mm:.2f} at k={quality.k:g})"
        style = _VERDICT_STYLE[row.verdict]
        lines.append(f"{name:<6} {row.measured_mm:9.2f} mm  nominal {row.nominal_mm:.2f} "
                     f"± {row.tolerance_mm:.2f}  deviation {row.deviation_mm:+.2f}{sigma}  "
                     f"[{style}]{row.verdict}[/]")
    verdict = quality.verdict
    lines.append(f"[bold {_VERDICT_STYLE[verdict]}]{verdict.upper()}[/]  " + ", ".join(
        f"{n} {c}" for c, n in ((quality.counts[v], v) for v in ("pass", "fail", "uncertain"))))
    return lines

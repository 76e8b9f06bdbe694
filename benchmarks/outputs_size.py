"""Bytes of each output for one 1280x1024 photo: at one point per pixel and at metric spacings.

Rows: the sample photo (samples/box.jpg, 1280x1024) and a rendered 1280x1024 oblique photo of a
box filling most of the frame (the densest cloud one photo gives), each at the default spacing
(one point per pixel) and at --spacing-mm values. Columns: every output the engine writes,
encoded exactly as `prism scan` and the worker write them (into memory), then

* compact = LAZ + glb + report (the issue's target: at most 4 MB per 1280x1024 photo),
* stored = what the service stores per photo for formats csv,ply (today's default) or for
  the compact formats: those files plus the preview and overlay.png it always writes.

Sizes depend on the photo's content (JPEG textures, LAZ's compression of colours); the run is
deterministic, timings are not reported (the machine is shared).

Run: .venv/bin/python benchmarks/outputs_size.py [--spacing 0.5 1.0]
"""

from __future__ import annotations

import argparse
import io
import json
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from prismcore import ScanSpec, run_scan
from prismcore.io.images import load_image
from prismcore.outputs.overlay_report import overlay_from_report
from prismcore.outputs.writers import encode_png, write_format, write_ply
from prismcore.report import report_dict
from prismcore.scan.cloud import decimate
from prismsynth import Box, render_oblique_view

ROOT = Path(__file__).resolve().parents[1]
FORMATS = ("csv", "ply", "las", "laz", "glb")
COMPACT = ("laz", "glb", "report")
LIMIT = 4 * 2**20


def _cases() -> list[tuple[str, np.ndarray, dict]]:
    job = json.loads((ROOT / "samples" / "job.json").read_text())
    sample = load_image(ROOT / "samples" / job["image"])
    box = Box(200.0, 140.0, 110.0)
    scene = render_oblique_view(box, image_size=(1280, 1024), distance_mm=420.0, seed=7)
    points = [scene.points[n] for n in ("p1", "p2", "p3", "p4", "p5", "p6", "p7")]
    rendered = {"image": "render.png", "points": points, "focal_px": scene.focal_px,
                "scale": {"kind": "edge", "edge": "width", "length_mm": box.width_mm}}
    return [("sample photo", sample, {k: v for k, v in job.items() if k != "formats"}),
            ("rendered, box fills the frame", scene.image, rendered)]


def sizes(image: np.ndarray, spec_data: dict, spacing: float | None) -> dict[str, int]:
    """{output: bytes} for one photo, plus its points."""
    spec = ScanSpec.model_validate({**spec_data, "formats": list(FORMATS), "spacing_mm": spacing})
    result = run_scan(spec, image)
    out: dict[str, int] = {"points": result.report.points or 0}
    for kind in FORMATS:
        buf = io.BytesIO()
        write_format(kind, buf, result.cloud, spec, report=result.report, images=[image])
        out[kind] = buf.tell()
    preview = decimate(result.cloud)
    out["preview"] = write_ply(io.BytesIO(), preview.points, preview.colors)
    out["overlay"] = len(encode_png(overlay_from_report(image, result.report)))
    out["report"] = len((json.dumps(report_dict(result.report), indent=2) + "\n").encode())
    out["compact"] = sum(out[k] for k in COMPACT)
    always = out["preview"] + out["overlay"] + out["report"]
    out["stored csv,ply"] = out["csv"] + out["ply"] + always
    out["stored compact"] = out["laz"] + out["glb"] + always
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, nargs="*", default=[0.5, 1.0],
                        help="spacings to compare with one point per pixel, mm")
    args = parser.parse_args()
    columns = ["points", *FORMATS, "preview", "overlay", "report", "compact", "stored csv,ply",
               "stored compact"]
    table = Table(title="bytes per 1280x1024 photo (MB = 2^20 bytes)")
    table.add_column("photo")
    table.add_column("spacing")
    for c in columns:
        table.add_column(c, justify="right")
    worst = 0
    for name, image, data in _cases():
        for spacing in [None, *args.spacing]:
            row = sizes(image, data, spacing)
            worst = max(worst, row["compact"])
            cells = [f"{row['points']:,}"] + [
                f"{row[c] / 2**20:.2f} MB" if row[c] >= 2**20 / 10 else f"{row[c] / 1024:.1f} kB"
                for c in columns[1:]]
            table.add_row(name, "per pixel" if spacing is None else f"{spacing:g} mm", *cells)
    Console(width=250).print(table)
    verdict = "met" if worst <= LIMIT else "NOT met"
    print(f"compact (LAZ + glb + report) at most {worst / 2**20:.2f} MB per photo: "
          f"target <= 4 MB {verdict}")


if __name__ == "__main__":
    main()

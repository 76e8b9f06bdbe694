"""The output formats and the files they write: the one table every other place reads.

A format is what a spec asks for (``"formats": ["csv", "laz"]``); it writes one file or several
(step: the solid and its JSON sidecar). Each file has its name (the same in the CLI's folders
and the service's object keys), the media type it is served with and the label the web page
links it by. The spec's `OutputFormat`, `FILE_NAMES`, the scale rule (`METRIC_FORMATS`), the
worker's media types and the page's labels (``web/src/formats.ts``, generated from this table)
all come from here. Standard library only: the spec and the API load it without numpy.

A new format is a row in `FORMAT_TABLE` (and its files in `FILES`), its name in `OutputFormat`,
and its writer in `prismcore.outputs.writers.write_format`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, cast, get_args

__all__ = ["FILES", "FILE_NAMES", "FORMATS", "FORMAT_TABLE", "METRIC_FORMATS", "PART_FORMATS",
           "Format", "OutputFile", "OutputFormat", "media_type", "output_files"]


@dataclass(frozen=True)
class OutputFile:
    """One file a scan (or a job) may leave: its kind's file name, media type and link label."""

    name: str
    """The file's name, in a CLI folder and in a job's object keys."""
    media_type: str
    """The type it is stored and served with (IANA's where there is one: model/step, image/vnd.dxf)."""
    label: str | None = None
    """The web page's download link text; None: not offered as a download."""
    frame_label: str | None = None
    """Its shorter link text in a video's table of frames; None: not linked there."""


@dataclass(frozen=True)
class Format:
    """One output format a spec may ask for."""

    files: tuple[str, ...]
    """The kinds (`FILES`' keys) it writes, in order."""
    needs_scale: bool
    """In millimetres (or metres): a scan without a scale, in pixels, cannot have it."""
    part: bool = False
    """Written from the measurement alone (no cloud), so a joint fit has it too."""


FILES: dict[str, OutputFile] = {
    # The downloads, in the order the page lists their links (a video's frames: the ones with a
    # frame label, in the same order).
    "csv": OutputFile("cloud.csv", "text/csv", "Cloud (CSV)", "CSV"),
    "ply": OutputFile("cloud.ply", "application/octet-stream", "Cloud (PLY)", "PLY"),
    "las": OutputFile("cloud.las", "application/vnd.las", "Cloud (LAS)", "LAS"),
    "laz": OutputFile("cloud.laz", "application/vnd.laszip", "Cloud (LAZ)", "LAZ"),
    "glb": OutputFile("box.glb", "model/gltf-binary", "Box model (glTF .glb)", "Box model"),
    "stl": OutputFile("box.stl", "model/stl", "Box mesh (STL)", "STL"),
    "step": OutputFile("part.step", "model/step", "CAD solid (STEP)", "STEP"),
    "step_meta": OutputFile("part.step.json", "application/json", "CAD solid's dimensions (JSON)"),
    "drawing_pdf": OutputFile("drawing.pdf", "application/pdf", "Drawing (PDF)", "Drawing (PDF)"),
    "drawing_svg": OutputFile("drawing.svg", "image/svg+xml", "Drawing (SVG)"),
    "drawing_dxf": OutputFile("drawing.dxf", "image/vnd.dxf", "Drawing (DXF)", "DXF"),
    "report": OutputFile("report.json", "application/json", "Report (JSON)", "Report"),
    "joint": OutputFile("joint.json", "application/json", "Report (JSON)"),
    # The overlay's name is its base: it is stored with its picture format's suffix
    # (`prismcore.outputs.writers.overlay_name`), and served with that format's type: PNG here
    # is `prism scan`'s default; the worker stores JPEG (`prismcore.outputs.overlay_media_type`).
    "overlay": OutputFile("overlay.png", "image/png", "Fit overlay"),
    "overlay_side": OutputFile("overlay_side.png", "image/png"),
    "preview": OutputFile("preview.ply", "application/octet-stream"),
    "summary": OutputFile("summary.json", "application/json"),
    "tracked_points": OutputFile("tracked_points.json", "application/json"),
}
"""Every file kind a scan or a job leaves."""

OutputFormat = Literal["csv", "ply", "las", "laz", "glb", "step", "drawing", "stl"]
"""The names of `FORMAT_TABLE` (spelled out for the type checker; checked equal at import)."""

FORMAT_TABLE: dict[str, Format] = {
    "csv": Format(("csv",), needs_scale=False),
    "ply": Format(("ply",), needs_scale=False),
    "las": Format(("las",), needs_scale=True),
    "laz": Format(("laz",), needs_scale=True),
    "glb": Format(("glb",), needs_scale=True),
    "step": Format(("step", "step_meta"), needs_scale=True, part=True),
    "drawing": Format(("drawing_svg", "drawing_pdf", "drawing_dxf"), needs_scale=True, part=True),
    "stl": Format(("stl",), needs_scale=True, part=True),
}
"""The output formats a spec may ask for: the cloud as CSV, PLY, LAS or LAZ (compressed LAS),
the fitted box as a textured binary glTF model (glb), the part as a STEP solid (step: part.step
and its sidecar part.step.json), its dimensioned drawing (drawing: drawing.svg, drawing.pdf
and drawing.dxf) and the box as a binary STL mesh (stl: box.stl)."""

if tuple(FORMAT_TABLE) != get_args(OutputFormat):  # pragma: no cover - a table edited by half
    raise RuntimeError("OutputFormat and FORMAT_TABLE name different formats")

FORMATS = cast("tuple[OutputFormat, ...]", tuple(FORMAT_TABLE))
"""The format names, in the table's order."""

METRIC_FORMATS = tuple(f for f in FORMATS if FORMAT_TABLE[f].needs_scale)
"""The formats in millimetres (or metres): a scan without a scale, in pixels, cannot have them."""

PART_FORMATS = tuple(f for f in FORMATS if FORMAT_TABLE[f].part)
"""The formats written from the measurement alone (the part's STEP solid and drawing): a joint fit
has them too."""

FILE_NAMES: dict[str, str] = {kind: file.name for kind, file in FILES.items()}
"""The file name of each output kind, the same in the CLI's folders and the service's keys."""


def output_files(formats: Sequence[str]) -> list[str]:
    """The file kinds (`FILES`' keys) the formats write, in order: a format writes the file of its
    own name, except step (the solid and its JSON sidecar) and drawing (SVG, PDF, DXF)."""
    return [kind for f in formats for kind in (FORMAT_TABLE[f].files if f in FORMAT_TABLE else (f,))]


def media_type(kind: str) -> str:
    """The media type the file of `kind` is stored with.

    Raises
    ------
    KeyError
        A kind the table does not have (a new file needs its row).
    """
    return FILES[kind].media_type

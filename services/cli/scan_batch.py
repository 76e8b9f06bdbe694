"""`prism scan PHOTOS... --station station.json --out DIR` (or `--board board.json`, hand-held) and
`prism scan [PHOTOS...] --points-table points.csv --out DIR`: many photos measured in ONE process,
each as a part of its own.

The engine's imports (numpy, OpenCV, the fits) and the station are loaded once, then each photo is
measured by the same code a single photo is (`station_scan`, or the runner of its spec's kind,
`scan_runners.RUNNERS`) into its own folder, ``DIR/<photo's name>/``, its printout replaced by one
progress line as it finishes. A photo that fails (unreadable, no part found, its points refused)
is named with the reason and the others are measured; the table of them all, ``results.csv`` and
``results.json``, has the service's columns, built by the same function
(`prism_common.results_rows.result_row`).

A points table (`read_points_table`) is a CSV file with a header line: ``file`` (the photo, its
path relative to the table's folder, or as given on the command line) and ``points`` (seven points
"x1,y1 x2,y2 ...", or auto), and optionally ``reference`` (your id for the part, in the results'
item_reference), ``width_mm``, ``height_mm``, ``depth_mm``, ``distance_mm``, ``mm_per_px``,
``focal_px`` (a row's scale and focal length: the command line's are used for a row without),
``side_face``, ``nominal`` ("W,H,D") and ``tolerance_mm``. Each row is one part measured alone
(`--points-file` is one part in several photos, fitted jointly).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from prismcore.errors import InputError

if TYPE_CHECKING:
    from prismcore.report import ScanReport
    from prismcore.spec import ScanSpec

__all__ = ["PHOTO_FLAGS", "TABLE_COLUMNS", "BatchPhoto", "folders", "read_points_table", "report_of",
           "run_batch"]

_SCALES = ("width_mm", "height_mm", "depth_mm", "distance_mm", "mm_per_px")
TABLE_COLUMNS = ("file", "points", "reference", *_SCALES, "focal_px", "side_face", "nominal",
                 "tolerance_mm")
"""The columns a points table may have (file and points are needed)."""

PHOTO_FLAGS = (*_SCALES, "focal_px", "side_face", "nominal", "tolerance_mm")
"""What a row may set for its photo instead of the command line."""


@dataclass(frozen=True)
class BatchPhoto:
    """One photo of a batch: its path, its folder's name under --out, its spec (a clicked or found
    photo's; None on a station or a board) and the client's reference for it."""

    path: Path
    folder: str
    spec: ScanSpec | None = None
    reference: str | None = None


def folders(paths: Iterable[Path]) -> list[str]:
    """Each photo's folder name: its name without the suffix, ``-2``, ``-3``... after a name
    already taken (parts/1.jpg and spares/1.jpg go to 1/ and 1-2/)."""
    taken: set[str] = set()
    names = []
    for path in paths:
        name, n = path.stem or path.name, 1
        while (name if n == 1 else f"{name}-{n}") in taken:
            n += 1
        names.append(name if n == 1 else f"{name}-{n}")
        taken.add(names[-1])
    return names


def read_points_table(table: Path, images: list[Path], spec_for: Callable[[Path, dict[str, str]], ScanSpec]
                      ) -> list[BatchPhoto]:
    """The photos of a points table: those given (each found in the table by its path or its
    name), else every row's (relative to the table's folder); their specs made by `spec_for`
    (photo, the row's values). InputError naming the table's line for a bad row."""
    try:
        with table.open(newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            header = [c.strip() for c in reader.fieldnames or []]
            rows = [({(k or "").strip(): (v or "").strip() for k, v in row.items()}, reader.line_num)
                    for row in reader]
    except OSError as exc:
        raise InputError(f"cannot read --points-table {str(table)!r}: {exc.strerror}") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"--points-table {str(table)!r} is not a CSV table: {exc}") from None
    unknown = [c for c in header if c not in TABLE_COLUMNS]
    if "file" not in header or "points" not in header or unknown:
        raise InputError(f"--points-table {str(table)!r}: columns file, points and any of "
                         f"{', '.join(TABLE_COLUMNS[2:])}"
                         + (f"; not {', '.join(map(repr, unknown))}" if unknown else ""))
    if not rows:
        raise InputError(f"--points-table {str(table)!r} has no rows")
    by_file: dict[str, tuple[dict[str, str], int]] = {}
    for row, line in rows:
        if row["file"] in by_file:
            raise InputError(f"{table} line {line}: {row['file']!r} again (line {by_file[row['file']][1]})")
        by_file[row["file"]] = (row, line)
    if images:
        chosen = []
        for image in images:
            found = by_file.get(str(image)) or by_file.get(image.name)
            if found is None:
                raise InputError(f"{image}: no row in --points-table {str(table)!r} (its file column "
                                 f"names it as {str(image)!r} or {image.name!r})")
            chosen.append((image, *found))
    else:
        chosen = [(table.parent / row["file"], row, line) for row, line in rows]
    photos = []
    for (path, row, line), folder in zip(chosen, folders(p for p, _, _ in chosen), strict=True):
        if not path.is_file():
            raise InputError(f"{table} line {line}: no photo {str(path)!r}")
        try:
            spec = spec_for(path, {k: v for k, v in row.items() if (k in PHOTO_FLAGS or k == "points") and v})
        except InputError as exc:
            raise InputError(f"{table} line {line} ({row['file']}): {exc}") from None
        photos.append(BatchPhoto(path, folder, spec, row.get("reference") or None))
    return photos


def _sizes(report: ScanReport) -> str:
    dims, sigma = report.dimensions, report.uncertainty
    return " x ".join(f"{getattr(dims, k):.2f}" + ("" if sigma is None else f" ± {getattr(sigma, k):.2f}")
                      for k in ("width", "height", "depth")) + f" {dims.unit}"


def run_batch(photos: list[BatchPhoto], out: Path, measure: Callable[[BatchPhoto, Path], ScanReport]
              ) -> int:
    """Measure each photo by `measure` (photo, its folder; returns its report), print a line as each
    finishes, write results.csv and results.json in `out`; returns how many failed."""
    from prism_common.report_result import item_result
    from prism_common.results_rows import csv_chunks, json_chunks, result_row

    from .console import rich_console as console

    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    failed: list[str] = []
    verdicts = {"pass": 0, "fail": 0, "uncertain": 0}
    wide = len(str(len(photos)))
    started = time.perf_counter()
    for i, photo in enumerate(photos):
        folder = out / photo.folder
        head = f"[{i + 1:>{wide}}/{len(photos)}] {photo.path}"
        try:
            with console().capture():  # the photo's own printout: its line below says it
                report = measure(photo, folder)
        except Exception as exc:  # one photo's failure, whatever it is, is its row's
            reason = str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
            failed.append(str(photo.path))
            console().print(f"{head}  [red]failed:[/] {reason}", soft_wrap=True, highlight=False)
            rows.append(result_row(spec=photo.spec, state="failed", error=reason, result=None,
                                   input=str(photo.path), file_name=photo.path.name, item=i,
                                   item_reference=photo.reference))
            continue
        result = item_result(report)
        if result.quality and result.quality.get("verdict") in verdicts:
            verdicts[result.quality["verdict"]] += 1
        rows.append(result_row(spec=photo.spec, state="succeeded", error=None, result=result,
                               input=str(photo.path), file_name=photo.path.name, item=i,
                               item_reference=photo.reference))
        warned = len(result.warnings)
        notes = [f"{warned} warning{'s' * (warned != 1)}"] if warned else []
        if result.quality:
            notes.insert(0, str(result.quality["verdict"]).upper())
        console().print(f"{head}  {_sizes(report)}" + "".join(f"  {n}" for n in notes)
                        + f"  -> {folder}", soft_wrap=True, highlight=False)
    state = ("succeeded" if not failed else "failed" if len(failed) == len(photos)
             else "completed_with_failures")
    (out / "results.csv").write_text("".join(csv_chunks([rows])), encoding="utf-8", newline="")
    head_doc = {"job_id": None, "client_reference": None, "state": state, "verdicts": verdicts}
    (out / "results.json").write_text("".join(json_chunks(head_doc, [rows])), encoding="utf-8")
    seconds = time.perf_counter() - started
    console().print(f"{len(photos) - len(failed)} of {len(photos)} photos measured in {seconds:.1f} s"
                    + (f", {len(failed)} failed: {', '.join(failed)}" if failed else "")
                    + f"; results: {out / 'results.csv'}", soft_wrap=True, highlight=False)
    return len(failed)


def report_of(folder: Path) -> ScanReport:
    """The report.json a runner wrote in `folder`."""
    from prismcore.report import ScanReport

    return ScanReport.model_validate_json((folder / "report.json").read_text())

"""`prism results JOB`: the job's results table (``GET /v1/jobs/{id}/results.json``) in the
terminal, a row per item and per video frame, verdicts coloured."""

from __future__ import annotations

from typing import Any

from prism_common.public import ResultsTable
from rich.console import Console
from rich.markup import escape
from rich.table import Table

__all__ = ["render_results"]

_COLOURS = {"pass": "green", "fail": "bold red", "uncertain": "yellow"}


def _number(value: Any, digits: int = 2) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def _dimension(row: dict[str, Any], name: str) -> str:
    if row.get(name) is None:
        return ""
    text = _number(row[name])
    if row.get(f"{name}_sigma") is not None:
        text += f" ± {row[f'{name}_sigma']:.2f}"
    if (verdict := row.get(f"{name}_verdict")) is not None:
        text = f"[{_COLOURS.get(verdict, '')}]{text}[/]"
    return text


def render_results(table: ResultsTable, console: Console) -> None:
    """Print `table`: a line on the job, then a row per item (and frame), errors in full."""
    counts = ", ".join(f"{n} {v}" for v, n in table.verdicts.items() if n)
    console.print(f"job {table.job_id}: [bold]{table.state.value}[/]"
                  + (f"  ({table.client_reference})" if table.client_reference else "")
                  + (f"  verdicts: {counts}" if counts else ""), soft_wrap=True)
    out = Table(show_edge=False, pad_edge=False)
    for name, justify in (("item", "right"), ("frame", "right"), ("state", "left"),
                          ("width", "right"), ("height", "right"), ("depth", "right"),
                          ("unit", "left"), ("points", "right"), ("loss", "right"),
                          ("source", "left"), ("verdict", "left"), ("error", "left")):
        out.add_column(name, justify=justify)  # type: ignore[arg-type]
    for row in table.rows:
        verdict = row.get("verdict")
        out.add_row(
            str(row["item"]), "" if row.get("frame") is None else str(row["frame"]), row["state"],
            *(_dimension(row, d) for d in ("width", "height", "depth")), row.get("unit") or "",
            "" if row.get("cloud_points") is None else f"{row['cloud_points']:,}",
            "" if row.get("point_loss") is None else f"{100 * row['point_loss']:.1f}%",
            row.get("points_source") or "",
            f"[{_COLOURS.get(verdict, '')}]{verdict.upper()}[/]" if verdict else "",
            escape(row.get("error") or ""))
    # Piped or captured, the table keeps every column rather than squeeze into 80.
    wide = console if console.is_terminal else Console(file=console.file, width=200, color_system=None)
    wide.print(out)

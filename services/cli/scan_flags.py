"""`prism scan`'s and `prism submit`'s flags as a job spec: the scale, the points, the quality
and frame flags read into the spec's fields, a spec file read as JSON, and a spec's validation
error told in one line by the option that gave the field. `prism scan`'s single photos, videos
and points table (`batch_command`) and `prism submit` (`client_commands`) share them.

Pydantic and the spec's model are imported where a function runs: `prism --help` imports this
module through the commands (tests/cli/test_cli_imports.py).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from prismcore.errors import InputError

if TYPE_CHECKING:
    from pydantic import ValidationError

    from prismcore.spec import ScanSpec

__all__ = ["one_line", "quality_flags", "read_spec_json", "scale_from_flags", "scale_options",
           "selection_from_flags", "spec_from_flags"]


def _internal(step: int | str) -> bool:
    return isinstance(step, str) and ("[" in step or step.startswith(("constrained-", "function-")))


# A bound pydantic names ("Input should be greater than 0") as the option's rule ("must be > 0").
_BOUNDS = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="), "less_than": ("lt", "<"),
           "less_than_equal": ("le", "<=")}


def _option_rule(option: str, first: Mapping[str, Any], message: str) -> str:
    """The error told by the option's name: what its value must be ("--width-mm must be > 0"),
    or the model's own reason after it."""
    bound = _BOUNDS.get(str(first.get("type")))
    ctx = first.get("ctx") or {}
    if bound is not None and bound[0] in ctx:
        return f"{option} must be {bound[1]} {ctx[bound[0]]:g}"
    if first.get("type") == "finite_number":
        return f"{option} must be a finite number"
    return f"{option}: {message}"


def one_line(error: ValidationError, options: Mapping[str, str] | None = None) -> str:
    """A spec's validation error as one line: where, what, how many more. `options` maps a spec
    field ("scale.edge.length_mm") to the command-line option that gave it ("--width-mm"): an
    error there is told by the option's name ("--width-mm must be > 0")."""
    from prismcore.spec import error_message

    first = error.errors()[0]
    # Steps that name pydantic's own validators ("function-after[check(), constrained-float]",
    # a branch of a union) are not in the spec: left out.
    where = ".".join(str(p) for p in first["loc"] if not _internal(p)) or "spec"
    more = f" (and {error.error_count() - 1} more)" if error.error_count() > 1 else ""
    # A validator's message that names its field already ("views: ...") is not prefixed again.
    message = error_message(first["msg"])
    if options and where in options:
        return f"{_option_rule(options[where], first, message)}{more}"
    if message.startswith((f"{where}:", f"{where} ")):
        return f"{message}{more}"
    return f"{where}: {message}{more}"


def scale_from_flags(mm_per_px: str | None, distance_mm: float | None, width_mm: float | None,
           height_mm: float | None, depth_mm: float | None) -> dict | None:
    given = [v is not None for v in (mm_per_px, distance_mm, width_mm, height_mm, depth_mm)]
    if sum(given) > 1:
        raise InputError("give one scale: --mm-per-px, --distance-mm, or one of "
                         "--width-mm/--height-mm/--depth-mm")
    if mm_per_px is not None:
        try:
            values = [float(v) for v in mm_per_px.split(",")]
        except ValueError:
            raise InputError(f"--mm-per-px {mm_per_px!r}: expected F or FRONT,SIDE") from None
        if len(values) not in (1, 2):
            raise InputError(f"--mm-per-px {mm_per_px!r}: expected F or FRONT,SIDE")
        return {"kind": "mm_per_px", "front": values[0],
                "side": values[1] if len(values) == 2 else None}
    if distance_mm is not None:
        return {"kind": "pinhole", "distance_mm": distance_mm}
    for edge, length in (("width", width_mm), ("height", height_mm), ("depth", depth_mm)):
        if length is not None:
            return {"kind": "edge", "edge": edge, "length_mm": length}
    return None


def scale_options(mm_per_px: str | None = None, distance_mm: float | None = None,
                  width_mm: float | None = None, height_mm: float | None = None,
                  depth_mm: float | None = None) -> dict[str, str]:
    """The spec fields the scale options fill, each named by its option (for `one_line`); the
    known edge's length also as a lone KnownEdge's field (a joint fit validates it alone)."""
    options = {"focal_px": "--focal-px", "spacing_mm": "--spacing-mm", "max_pixels": "--max-pixels",
               "tolerance": "--tolerance", "scale.pinhole.distance_mm": "--distance-mm",
               "scale.mm_per_px.front": "--mm-per-px", "scale.mm_per_px.side": "--mm-per-px SIDE"}
    for flag, value in (("--width-mm", width_mm), ("--height-mm", height_mm), ("--depth-mm", depth_mm)):
        if value is not None:
            options["scale.edge.length_mm"] = options["length_mm"] = flag
    return options


def _mm_values(flag: str, text: str, counts: tuple[int, ...], expected: str) -> list[float]:
    """'100,80,60' -> [100.0, 80.0, 60.0]; a bad number or count names the flag and the text."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{flag} {text!r}: expected {expected} in mm") from None
    if len(values) not in counts or not all(math.isfinite(v) for v in values):
        raise InputError(f"{flag} {text!r}: expected {expected} in mm")
    return values


def quality_flags(nominal: str | None, tolerance_mm: str | None) -> dict[str, Any]:
    """The spec's `nominal` and `tolerance_mm` from ``--nominal W,H,D --tolerance-mm T|Tw,Th,Td``."""
    if (nominal is None) != (tolerance_mm is None):
        raise InputError("--nominal and --tolerance-mm go together: give both")
    if nominal is None or tolerance_mm is None:
        return {}
    tol = _mm_values("--tolerance-mm", tolerance_mm, (1, 3), "T or Tw,Th,Td")
    sizes = _mm_values("--nominal", nominal, (3,), "W,H,D")
    if min(tol) < 0:
        raise InputError(f"--tolerance-mm {tolerance_mm!r}: a tolerance is >= 0 mm")
    if min(sizes) <= 0:
        raise InputError(f"--nominal {nominal!r}: sizes are > 0 mm")
    return {"nominal": sizes,
            "tolerance_mm": tol[0] if len(tol) == 1 else tol}


def spec_from_flags(image: Path | None, points: str | None, **flags: Any) -> ScanSpec:
    if image is None or points is None:
        raise InputError("give IMAGE and --points, or --spec FILE")
    from prismcore.spec import ScanSpec

    formats = [f.strip() for f in flags.pop("formats", "csv,ply").split(",") if f.strip()]
    given = {k: flags.pop(k, None) for k in ("mm_per_px", "distance_mm", "width_mm", "height_mm", "depth_mm")}
    scale = scale_from_flags(**given)
    side = flags.pop("side", None)
    auto = _auto_points(points, flags.pop("hint", None), flags.pop("roi", None))
    flags.update(quality_flags(flags.pop("nominal", None), flags.pop("tolerance_mm", None)))
    from pydantic import ValidationError

    try:
        return ScanSpec.model_validate({
            "image": str(image), "side_image": str(side) if side else None,
            **auto, "scale": scale, "formats": formats,
            "csv": {"header": flags.pop("csv_header", False), "colors": flags.pop("csv_colors", False)},
            **flags,
        })
    except ValidationError as exc:  # a bad option's value: told by the option's name
        raise InputError(one_line(exc, scale_options(**given))) from None


def _numbers(flag: str, text: str, count: int) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        shape = "X,Y" if count == 2 else "X0,Y0,X1,Y1"
        raise InputError(f"{flag} {text!r}: expected {shape} in image pixels")
    return values


def _auto_points(points: str, hint: str | None, roi: str | None) -> dict[str, object]:
    """The spec's points (and auto_points) from --points, --hint and --roi."""
    if points.strip() != "auto":
        if hint is not None or roi is not None:
            raise InputError("--hint and --roi go with --points auto")
        from prismcore.spec import parse_points

        try:
            return {"points": parse_points(points).model_dump()}
        except ValueError as exc:
            raise InputError(f"--points: {exc}") from None
    if hint is not None and roi is not None:
        raise InputError("give --hint or --roi, not both")
    return {"points": "auto", "auto_points": {
        "hint": None if hint is None else _numbers("--hint", hint, 2),
        "roi": None if roi is None else _numbers("--roi", roi, 4)}}


def selection_from_flags(every: int | None, start: float | None, end: float | None,
                         frames: str | None, sharpest: int | None) -> dict | None:
    """The spec's `frames` from the CLI flags; None when no flag was given."""
    selection: dict = {"every": every, "start_s": start, "end_s": end, "sharpest": sharpest}
    if frames is not None:
        try:
            selection["indices"] = [int(v) for v in frames.split(",") if v.strip()]
        except ValueError:
            raise InputError(f"--frames {frames!r}: expected frame indices like 0,5,9") from None
    given = {k: v for k, v in selection.items() if v is not None}
    return given or None


def read_spec_json(path: Path) -> Any:
    """A spec file's JSON, or an InputError saying in one line why it cannot be read."""
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"cannot read spec {str(path)!r}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"spec {str(path)!r} is not JSON: {exc.msg} at line {exc.lineno}") from None
    except UnicodeDecodeError:
        raise InputError(f"spec {str(path)!r} is not JSON: not UTF-8 text") from None

"""`prism station verify`: a station checked against a reference part of known size, placed
several times across the support. The statistics and the verdict are the engine's
(`prismcore.station.verify`); this measures the photos, prints the figures and stores them."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prismcore import InputError

from .client_commands import ApiKey, ApiUrl
from .client_commands import _client as client
from .station_command import console, load_station

if TYPE_CHECKING:
    from prism_common.stations import VerificationPublic

    from prismcore.station import Verification

__all__ = ["parse_reference", "verify"]

def parse_reference(text: str) -> tuple[float, float, float]:
    """--reference W,D,H (mm) as three numbers; anything else exits 2 quoting it."""
    from prismcore.station import parse_reference as parse

    return parse(text)


def verify(
    station_file: Annotated[
        str,
        typer.Argument(
            metavar="station",
            help="station.json (prism station calibrate); the verification is stored in it. With "
            "--remote: the service's station id (prism station upload, prism station list).",
        ),
    ],
    photos: Annotated[
        list[Path],
        typer.Argument(
            help="Photos of the reference part, placed at least 5 times at "
            "different positions and yaws across the support."
        ),
    ],
    reference: Annotated[
        str,
        typer.Option(
            help="The reference part's true size W,D,H in mm, as the station "
            "reports it: width >= depth (the footprint's sides), then height."
        ),
    ],
    tolerance: Annotated[
        float | None,
        typer.Option(
            help="T of the tolerance +-T, mm: %GRR is judged against "
            "its full width 2T, and a bias under 10 % of 2T is "
            "accepted."
        ),
    ] = None,
    remote: Annotated[
        bool,
        typer.Option(
            "--remote",
            help="Verify the service's station named by its id: the photos are sent to "
            "POST /v1/stations/{id}/verifications, measured there and the verification stored "
            "with the station (its history: GET /v1/stations/{id}/verifications).",
        ),
    ] = False,
    api: ApiUrl = "http://127.0.0.1:8000",
    key: ApiKey = "",
) -> None:
    """Verify a station with a reference part of known size (a gauge block, a box measured with
    calipers), photographed in several placements across the support. Prints and stores in
    station.json, per dimension: the bias (mean error) with its 95 % confidence interval (Student's
    t), the repeatability (the errors' sample sigma over the placements), whether each placement's
    error lies within 3 times its own stated sigma, and %GRR = 6 x repeatability / tolerance x 100
    (AIAG MSA; the tolerance's full width 2T; repeatability alone: one station, one operator).
    Verified when each dimension's bias is not significant (its 95 % interval holds 0) or at most
    10 % of 2T, its %GRR is at most 30 %, and every placement lies within its 3 sigma. Exit 0
    verified, 1 not verified, 2 bad input (fewer than 5 placements, placements not spread over the
    support, or a placement showing the camera one side of the part only, refused with the reason)."""
    from prismcore.io import load_image
    from prismcore.station import check_count, verify_station

    size = parse_reference(reference)
    check_count(len(photos))
    if tolerance is not None and not tolerance > 0:
        raise InputError(f"tolerance {tolerance:g}: expected T > 0 (mm, for +-T)")
    if remote:
        missing = [p for p in photos if not p.is_file()]
        if missing:
            raise InputError(f"{missing[0]}: no such file")
        with client(api, key) as service:
            found = service.verify_station(station_file, photos, size, tolerance)
        _print(found)
        console().print(f"stored with station {station_file} on the service (verification {found.id}, "
                        f"{found.date:%Y-%m-%d %H:%M} UTC)", markup=False)
        if not found.verified:
            raise typer.Exit(1)
        return
    path = Path(station_file)
    station = load_station(path)
    done = verify_station(station, [(str(p), load_image(p)) for p in photos], size, tolerance,
                          datetime.now(UTC).replace(microsecond=0))
    _print(done)
    path.write_text(station.model_copy(update={"verification": done}).model_dump_json(indent=2) + "\n")
    console().print(f"stored in {path} (verification, {done.date:%Y-%m-%d %H:%M} UTC)", markup=False)
    if not done.verified:
        raise typer.Exit(1)


def _print(done: Verification | VerificationPublic) -> None:
    out = console()
    names = list(done.dimensions)
    wide = max(len(p) for p in done.photos)
    out.print(
        f"{'':2}{'photo':<{wide}}  {'position mm':>14}  {'yaw':>5}  "
        + "  ".join(f"{n + ' error':>14}" for n in names)
        + "  (error ± 3 sigma, mm; ! outside it)",
        markup=False,
    )
    for i, photo in enumerate(done.photos):
        x, y = done.positions_mm[i]
        cells = []
        for d in done.dimensions.values():
            flag = " " if d.within_3_sigma[i] else "!"
            cells.append(f"{d.errors_mm[i]:+6.2f} ± {3 * d.sigmas_mm[i]:4.2f}{flag}")
        out.print(
            f"{i + 1:<2}{photo:<{wide}}  ({x:6.1f}, {y:5.1f})  {done.yaws_deg[i]:5.1f}  "
            + "  ".join(f"{c:>14}" for c in cells),
            markup=False,
        )
    out.print(
        f"{'':9}{'reference':>9}  {'bias':>6}  {'95 % CI':>16}  {'repeatability':>13}  "
        f"{'within 3 sigma':>14}  {'%GRR':>6}",
        markup=False,
    )
    for name, d in done.dimensions.items():
        low, high = d.bias_ci95_mm
        grr = "-" if d.grr_percent is None else f"{d.grr_percent:.1f} %"
        inside = f"{sum(d.within_3_sigma)} of {len(d.within_3_sigma)}"
        verdict = "ok" if d.verified else "FAILS"
        out.print(
            f"{name:<9}{d.reference_mm:9.2f}  {d.bias_mm:+6.3f}  [{low:+6.3f}, {high:+6.3f}]  "
            f"{d.repeatability_mm:13.3f}  {inside:>14}  {grr:>6}  {verdict}",
            markup=False,
        )
    tol = done.tolerance_mm
    if tol is None:
        out.print("%GRR: no --tolerance, not judged", markup=False)
    else:
        out.print(
            f"%GRR = 6 x repeatability / tolerance x 100, tolerance 2T = {2 * tol:g} mm (±{tol:g} mm): "
            "AIAG MSA's formula, repeatability alone (one station, one operator)",
            markup=False,
        )
    ref = " x ".join(f"{v:g}" for v in done.reference_mm.values())
    head = (
        f"{'verified' if done.verified else 'not verified'} on {done.date:%Y-%m-%d} with a {ref} mm "
        f"reference (width x depth x height), {len(done.photos)} placements"
    )
    out.print(head, markup=False)
    if done.verified:
        out.print(f"rule: {done.rule}", markup=False)
    else:
        for failure in done.decided_by:
            out.print(f"  {failure}", markup=False)
        out.print(f"rule: {done.rule}", markup=False)

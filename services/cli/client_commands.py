"""`prism submit`, `status`, `wait`, `download`, `results`, `jobs`, `cancel`: the job service
from scripts."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from prismcore.errors import InputError

from .console import rich_console as console
from .scan_flags import one_line, read_spec_json, spec_from_flags

if TYPE_CHECKING:
    from prism_common.public import JobPublic, ResultPublic

    from .client import ApiClient

# The client (httpx, the API's pydantic models) is imported when a command talks to the API, not
# for `prism --help` or `prism scan` (tests/cli/test_cli_imports.py).

__all__ = ["cancel", "download", "jobs", "results", "station_delete", "station_list", "station_upload",
           "status", "submit", "wait"]

ApiUrl = Annotated[str, typer.Option("--api", envvar="PRISM_API_URL", help="API base URL.")]
ApiKey = Annotated[str, typer.Option("--key", envvar="PRISM_API_KEY", help="API key.")]
_REFERENCE_PREFIXES = ("upload:", "s3://", "https://")


def _client(api: str, key: str) -> ApiClient:
    if not key:
        raise InputError("no API key: pass --key or set PRISM_API_KEY")
    from .client import ApiClient

    return ApiClient(api, key)


def _upload_local(client: ApiClient, item: dict, base: Path) -> dict:
    """Replace local file paths in an item (and its views) by upload references (uploading them)."""
    views = item.get("views")
    if isinstance(views, list):  # copies: the caller's document stays as it was read
        views = item["views"] = [dict(v) if isinstance(v, dict) else v for v in views]
    places = [(item, field, field) for field in ("image", "side_image")] + (
        [(v, "image", f"views[{k}].image") for k, v in enumerate(views) if isinstance(v, dict)]
        if isinstance(views, list) else [])
    uploaded: dict[str, str] = {}  # a view's photo that is also the item's image is sent once
    for holder, field, name in places:
        value = holder.get(field)
        # Anything but a local path (a reference, a wrong type) goes as it is: the API judges it.
        if isinstance(value, str) and value and not value.startswith(_REFERENCE_PREFIXES):
            path = base / value
            if not path.is_file():
                raise InputError(f"{name} {value!r}: no such file")
            if value not in uploaded:
                uploaded[value] = client.upload(path)
            holder[field] = uploaded[value]
    return item


def _progress_text(job: JobPublic) -> str:
    """'3 of 10 items, about 40 s left' (the items part only when the job has more than one)."""
    from .client import format_eta, remaining_s

    parts = [f"{job.items_done} of {job.item_count} items"] if job.item_count > 1 else []
    if eta := format_eta(remaining_s(job)):
        parts.append(eta)
    return ", ".join(parts)


def _sizes(result: ResultPublic) -> str:
    """'120.00 ± 0.59 x 79.99 ± 0.59 x 59.98 ± 0.90 mm': each dimension with its 1-sigma
    uncertainty when the result has one (a video's median has none)."""
    d, sigma = result.dimensions, result.uncertainty or {}
    return " x ".join(f"{getattr(d, k):.2f}" + (" (given)" if k == result.given_dimension else
                                               f" ± {sigma[k]:.2f}" if k in sigma else "")
                      for k in ("width", "height", "depth")) + f" {d.unit}"


def _print_job(job: JobPublic) -> None:
    """The job's line, then per item its dimensions ± sigma and, on the lines after it, every
    warning its result carries (what report.json says about the measurement's trust)."""
    line = f"job {job.id}: [bold]{job.state.value}[/] {job.progress}%"
    if job.item_count > 1:
        line += f" ({job.items_done} of {job.item_count} items"
        line += f", {job.items_failed} failed)" if job.items_failed else ")"
    console().print(line, soft_wrap=True)
    if job.error:
        console().print(f"  error: {job.error}", soft_wrap=True, markup=False)
    for item in job.items:
        text = f"  item {item.index}: {item.state.value}"
        if item.result:
            text += f"  {_sizes(item.result)}, {item.result.points:,} points"
            if item.result.focal_px:
                text += f", focal {item.result.focal_px:.0f} px ({item.result.focal_source})"
        if item.error:
            text += f"  error: {item.error}"
        console().print(text, soft_wrap=True, markup=False)
        for warning in item.result.warnings if item.result else []:
            console().print(f"    warning: {warning}", soft_wrap=True, markup=False)


def _job_document(spec_file: Path) -> dict[str, Any]:
    """A --spec file as the job to send: a scan spec is the job's one item; a job document
    ({"items": [...], "client_reference", "webhook_url"}) is sent whole, so every field of it
    reaches the API (which refuses what it does not know, rather than the CLI dropping it)."""
    name = str(spec_file)
    data = read_spec_json(spec_file)
    if not isinstance(data, dict):
        raise InputError(f"spec {name!r}: expected a JSON object, a scan spec or {{\"items\": [...]}}")
    document = data if "items" in data else {"items": [data]}
    items = document["items"]
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise InputError(f"spec {name!r}: \"items\" must be a list of scan specs (JSON objects)")
    return document


def submit(
    api: ApiUrl = "http://127.0.0.1:8000",
    key: ApiKey = "",
    images: Annotated[list[Path] | None, typer.Argument(
        help="Photo (or give --spec); with --station, any number of photos, one item each.",
        metavar="IMAGE")] = None,
    station: Annotated[str | None, typer.Option(
        help="A stored station's id (prism station upload): each photo is measured on it, with no "
        "points and no scale.")] = None,
    points: Annotated[str | None, typer.Option(help="Reference points, as for prism scan.")] = None,
    spec_file: Annotated[Path | None, typer.Option("--spec", help="A scan spec or {items: [...]}.")] = None,
    side: Annotated[Path | None, typer.Option(help="Side photo.")] = None,
    mm_per_px: Annotated[str | None, typer.Option(help="F or FRONT,SIDE.")] = None,
    distance_mm: Annotated[float | None, typer.Option()] = None,
    focal_px: Annotated[float | None, typer.Option()] = None,
    width_mm: Annotated[float | None, typer.Option(help="Known real width.")] = None,
    height_mm: Annotated[float | None, typer.Option(help="Known real height.")] = None,
    depth_mm: Annotated[float | None, typer.Option(help="Known real depth.")] = None,
    method: Annotated[str, typer.Option()] = "default",
    cloud: Annotated[str, typer.Option()] = "surface",
    formats: Annotated[str | None, typer.Option(
        "--format", help="Outputs, comma-separated: csv, ply, las, laz, glb, step (the part as a "
        "STEP solid), drawing (its inspection drawing: SVG, PDF, DXF) (default: the service's, "
        "PRISM_DEFAULT_FORMATS).")] = None,
    nominal: Annotated[str | None, typer.Option(help="Nominal W,H,D in mm: verdicts per dimension.")] = None,
    tolerance_mm: Annotated[str | None, typer.Option(help="T or Tw,Th,Td, mm (with --nominal).")] = None,
    spacing_mm: Annotated[float | None, typer.Option(help="Thin the cloud to this spacing, mm.")] = None,
    webhook: Annotated[str | None, typer.Option(help="URL to POST the finished job to.")] = None,
    reference: Annotated[str | None, typer.Option(help="Your own reference for the job.")] = None,
    idempotency_key: Annotated[str | None, typer.Option(help="Resubmits return the same job.")] = None,
    then_wait: Annotated[bool, typer.Option("--wait", help="Wait for the job to finish.")] = False,
) -> None:
    """Submit a job (local files are uploaded first) and print its id; with --wait, exit 0 if it
    succeeded (every item), 1 otherwise (completed_with_failures, failed, cancelled)."""
    client = _client(api, key)
    from pydantic import ValidationError

    if spec_file is not None:
        document, base = _job_document(spec_file), spec_file.parent
        if station is not None:
            document["items"] = [{"station": station, **item} for item in document["items"]]
    elif station is not None:
        document, base = _station_document(images or [], station, formats), Path(".")
    else:
        if images and len(images) > 1:
            raise InputError(f"{len(images)} photos given: one photo per job without --station (give "
                             "several items in a --spec file)")
        image = images[0] if images else None
        try:
            spec = spec_from_flags(image, points, side=side, mm_per_px=mm_per_px,
                                   distance_mm=distance_mm, focal_px=focal_px, width_mm=width_mm,
                                   height_mm=height_mm, depth_mm=depth_mm, method=method, cloud=cloud,
                                   nominal=nominal, tolerance_mm=tolerance_mm, spacing_mm=spacing_mm,
                                   **({"formats": formats} if formats else {}))
        except ValidationError as exc:  # flags that make no spec (--format laz without a scale)
            raise InputError(one_line(exc)) from None
        # exclude_none, not exclude_defaults: a default that carries meaning (the scale's
        # `kind` tag) must reach the API, or it cannot tell one scale from another.
        item = spec.model_dump(mode="json", exclude_none=True)
        if not formats:
            del item["formats"]  # the service's default formats apply
        document, base = {"items": [item]}, Path(".")
    # The flags name the job's reference and webhook; given, they override the spec file's.
    if reference is not None:
        document["client_reference"] = reference
    if webhook is not None:
        document["webhook_url"] = webhook
    # The client uploads a file once however many items name it.
    body = {**document, "items": [_upload_local(client, dict(item), base) for item in document["items"]]}
    job = client.submit(body, idempotency_key=idempotency_key)
    console().print(job.id)
    if then_wait:
        _wait(client, job.id, timeout=3600)


def _station_document(images: list[Path], station: str, formats: str | None) -> dict[str, Any]:
    """One item per photo, each measured on `station` (the service's default formats unless given)."""
    if not images:
        raise InputError("--station: give the photos to measure on it")
    extra = {"formats": [f.strip() for f in formats.split(",") if f.strip()]} if formats else {}
    return {"items": [{"image": str(path), "station": station, **extra} for path in images]}


def station_upload(
    station_file: Annotated[Path, typer.Argument(help="station.json (prism station calibrate).")],
    name: Annotated[str | None, typer.Option(help="Your own name for it.")] = None,
    api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "",
) -> None:
    """Store a station on the service; prints its id (for prism submit --station ID)."""
    if not station_file.is_file():
        raise InputError(f"{station_file}: no such file")
    with _client(api, key) as client:
        found = client.create_station(station_file, name=name)
    console().print(found.id, soft_wrap=True)


def station_list(api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "") -> None:
    """List your stations on the service, newest first: id, image size, plane RMS, plate, name."""
    with _client(api, key) as client:
        for s in client.stations():
            console().print(f"{s.id}  {s.image_width}x{s.image_height} px  plane RMS "
                            f"{s.plane_rms_px:.2f} px  {'plate' if s.has_plate else 'no plate'}  "
                            f"{s.created_at:%Y-%m-%d %H:%M:%S}  {s.name or ''}", soft_wrap=True, markup=False)


def station_delete(station_id: str, api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "") -> None:
    """Delete one of your stations from the service."""
    with _client(api, key) as client:
        client.delete_station(station_id)
    console().print(f"deleted station {station_id}", soft_wrap=True)


def status(job_id: str, api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "",
           as_json: Annotated[bool, typer.Option("--json", help="Print the raw job.")] = False) -> None:
    """Print a job's state, progress and per-item results."""
    job = _client(api, key).job(job_id)
    console().print_json(job.model_dump_json()) if as_json else _print_job(job)


def _wait(client: ApiClient, job_id: str, timeout: float) -> JobPublic:
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TextColumn("{task.fields[detail]}"), TimeElapsedColumn(), console=console(),
                  transient=not console().is_terminal) as bar:
        task = bar.add_task(job_id, total=100, detail="")
        job = client.wait(job_id, timeout=timeout, on_update=lambda j: bar.update(
            task, completed=j.progress, description=f"{job_id} {j.state.value}",
            detail=_progress_text(j)))
    _print_job(job)
    if job.state != "succeeded":
        raise typer.Exit(1)
    return job


def wait(job_id: str, api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "",
         timeout: Annotated[float, typer.Option(help="Give up after this many seconds.")] = 3600) -> None:
    """Wait for a job with a progress bar; exit 0 if it succeeded (every item), 1 otherwise
    (completed_with_failures: some item failed; failed; cancelled)."""
    _wait(_client(api, key), job_id, timeout)


def download(job_id: str, out: Annotated[Path, typer.Option(help="Folder for the outputs.")],
             api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "") -> None:
    """Download every item's outputs into OUT/item-N/, and the job's table as OUT/results.csv."""
    with _client(api, key) as client:
        for path in client.download(client.job(job_id), out):
            console().print(str(path))
        console().print(str(client.save_results_csv(job_id, out / "results.csv")))


def results(job_id: str, api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "",
            as_json: Annotated[bool, typer.Option("--json", help="Print results.json.")] = False) -> None:
    """Print the job's results table: a row per item (and video frame), dimensions ± sigma, verdicts."""
    from .results_command import render_results

    with _client(api, key) as client:
        table = client.results(job_id)
    console().print_json(table.model_dump_json()) if as_json else render_results(table, console())


def jobs(api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "",
         state: Annotated[str | None, typer.Option(help="Only jobs in this state.")] = None,
         limit: Annotated[int, typer.Option(help="At most this many, newest first.", min=1)] = 20,
         as_json: Annotated[bool, typer.Option("--json", help="One JSON object per line.")] = False) -> None:
    """List your jobs, newest first: id, state, progress, items, when, your reference."""
    allowed = ("queued", "running", "succeeded", "completed_with_failures", "failed", "cancelled")
    if state is not None and state not in allowed:
        raise InputError(f"--state {state!r}: expected one of {', '.join(allowed)}")
    client = _client(api, key)
    for shown, job in enumerate(client.iter_jobs(state=state, page=min(limit, 200)), start=1):
        if as_json:
            print(job.model_dump_json(exclude={"items"}))
        else:
            console().print(f"{job.id}  {job.state.value:<9} {job.progress:>3}%  "
                          f"{job.items_done}/{job.item_count} items  "
                          f"{job.created_at:%Y-%m-%d %H:%M:%S}  {job.client_reference or ''}",
                          soft_wrap=True, markup=False)
        if shown >= limit:
            break


def cancel(job_id: str, api: ApiUrl = "http://127.0.0.1:8000", key: ApiKey = "") -> None:
    """Cancel a queued or running job; what had finished stays, the rest reads cancelled."""
    _print_job(_client(api, key).cancel(job_id))

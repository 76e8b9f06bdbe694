"""An item measured on a station (`"station": ID`): the photo alone, no points, no scale.

The tenant's station.json (`prism_common.stations`) is read once per process and kept by its
ETag (a HEAD per item tells a station deleted since, whose items then fail in words); the photo
is read where its reference points, measured by `prismcore.station.scan.scan_on_station` (the
station's fit gives the dimensions, its seven derived points make the cloud and the overlay) and
its outputs written as a photo item's (`artifacts.write_outputs`), report.json saying
``scale_source: "station"``. A photo the station cannot measure (no part, two parts, a part cut
by the edge, not a box resting flat, the camera moved) is an InputError: the item fails with the
engine's reason. Always whole in one task: the station's fit is one call, and its cloud is small.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from typing import TYPE_CHECKING, Any

from botocore.exceptions import ClientError
from prism_common.records import ItemResult, ItemView
from prism_common.stations import station_key
from prism_common.storage import is_missing

from prismcore import InputError
from prismcore.io import load_image
from prismcore.outputs import report_bytes
from prismcore.quality import report_quality
from prismcore.report import ScanReport

from .artifacts import item_key, item_result, write_outputs
from .context import WorkerContext
from .inputs import read_input

if TYPE_CHECKING:
    from prismcore.station import Station

__all__ = ["load_station", "measure_station"]

# The cloud's options a station item passes on to the scan of its derived points.
_CLOUD_FIELDS = ("formats", "tolerance", "cloud", "csv", "ply_ascii", "max_points", "spacing_mm")
_CACHED = 4  # a station.json is a few MB (its plate): a worker serves few stations at a time
_stations: OrderedDict[tuple[str, str], tuple[str, Station]] = OrderedDict()


def load_station(ctx: WorkerContext, tenant: str, station_id: str) -> Station:
    """The tenant's station, from this process's cache while its ETag is unchanged.

    Raises InputError when the tenant has no such station (deleted since the job was submitted).
    """
    from prismcore.station import Station

    key = station_key(tenant, station_id)
    try:
        etag = ctx.objects.client.head_object(Bucket=ctx.objects.bucket, Key=key)["ETag"]
    except ClientError as exc:
        if is_missing(exc):
            raise InputError(f"no station {station_id!r}: it was deleted after the job was "
                             "submitted") from None
        raise
    cached = _stations.get((tenant, station_id))
    if cached is not None and cached[0] == etag:
        _stations.move_to_end((tenant, station_id))
        return cached[1]
    station = Station.model_validate_json(ctx.objects.get_bytes(key))
    _stations[tenant, station_id] = (etag, station)
    while len(_stations) > _CACHED:
        _stations.popitem(last=False)
    return station


def measure_station(ctx: WorkerContext, view: ItemView) -> tuple[ItemResult, dict[str, str]]:
    """Measure the item's photo on its station and store the outputs; its result and their keys.

    Raises
    ------
    InputError
        The station is gone, the photo is unreadable or of another size than the station's
        camera, or the station cannot measure it (the engine's reason).
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    from prismcore.station import scan_on_station

    spec = view.item.spec
    assert spec.station is not None
    station = load_station(ctx, view.tenant, spec.station)
    limit = min(spec.max_pixels, ctx.settings.max_pixels)
    data, label = read_input(ctx, view, "front")
    photo = load_image(data, max_pixels=limit, name=label)
    del data
    camera = station.camera
    if photo.shape[:2] != (camera.image_height, camera.image_width):
        raise InputError(f"{label} is {photo.shape[1]}x{photo.shape[0]} px, station {spec.station}'s camera "
                         f"{camera.image_width}x{camera.image_height} px: a station measures photos of its "
                         "own camera at its image size")
    extra: dict[str, Any] = {name: getattr(spec, name) for name in _CLOUD_FIELDS
                             if getattr(spec, name) is not None}
    extra["max_pixels"] = limit
    extra = json.loads(json.dumps(extra, default=lambda v: v.model_dump(mode="json")))
    # the tolerance judges the camera's drift since calibration (prismcore.station.certify)
    done = scan_on_station(photo, station, label, extra, spec.tolerance_mm)
    report = done.report
    # The verdicts judge the station's dimensions (the derived points' scan never saw the nominal).
    report.quality = report_quality(report, spec.nominal, spec.tolerance_mm)
    if done.result is None or done.spec is None:
        return _report_only(ctx, view, report)
    return write_outputs(ctx, view.job_id, view.item.index, done.spec, done.result, [photo])


def _report_only(ctx: WorkerContext, view: ItemView,
                 report: ScanReport) -> tuple[ItemResult, dict[str, str]]:
    """The measurement stands but its derived points made no cloud (report.json says why)."""
    key = item_key(view.job_id, view.item.index, "report.json")
    ctx.objects.put_bytes(key, report_bytes(report), "application/json")
    return item_result(report), {"report": key}

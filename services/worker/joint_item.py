"""An item measured as ONE box from several views (`prismcore.multiview.joint.fit_views`), whole in one task.

Two kinds of item: one with `views` (photos of one part, each with its seven points; each read
where its reference points, not copied), and a video with `fit` "joint" (the frames of
`frame_points`, decoded from the video streamed to a local file; or with `points_frame`, the
points of one frame tracked to the selected frames (`prismcore.video.tracked`: tracked_points.json
is stored beside joint.json, the frames whose views differ most are fitted, and each frame the
tracking left out is named with its reason in the result's warnings and ``summary.tracking``).
The views are decoded and held together (at most `JOINT_MAX_VIEWS`, `JOINT_MAX_PIXELS`
together), fitted as one box, and the fit's report is stored as ``joint.json``; the item's
result carries the dimensions with their 1-sigma, the focal length, the views used and those
left out with the reason. No cloud is made: a cloud is one photo's.

Views of different image sizes (one camera is assumed), views none of which can be measured,
a video that does not decode: InputError, which fails the item with its reason.

Idempotent: the engine is deterministic and the report's key is fixed, so a re-run writes the same
object and result.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any

from prism_common.records import ItemResult, ItemView

from prismcore import InputError
from prismcore.io import VideoInfo, iter_frames, load_image
from prismcore.multiview import View, fit_views, joint_report
from prismcore.quality import quality_from_report
from prismcore.spec import JOINT_MAX_PIXELS, JOINT_NAME, TRACKED_NAME, KnownEdge
from prismcore.video import (
    Tracking,
    check_points_frame,
    joint_frames,
    probe_video,
    select_frames,
    tracked_views,
)

from .artifacts import item_key, put_part_files
from .context import WorkerContext
from .inputs import read_reference, save_input
from .steps import max_pixels
from .video import client_message, track_item

__all__ = ["measure_joint"]


def measure_joint(ctx: WorkerContext, view: ItemView) -> tuple[ItemResult, dict[str, str]]:
    """Measure the item's views as one box, store joint.json; the result and {"joint": key}.

    Raises
    ------
    InputError
        A photo or video that is not readable, views of different sizes, no view measurable.
    ReferenceError, FetchError
        An input that may not or could not be read.
    """
    spec = view.item.spec
    inputs: dict[str, Any]
    labels: list[int] | None
    tracking: Tracking | None = None
    if spec.views is not None:
        views, labels, inputs = _photos(ctx, view), None, {
            "inputs": [{"index": k, "image": v.image} for k, v in enumerate(spec.views)]}
    elif spec.points_frame is not None:
        views, frames, info, tracking = _tracked(ctx, view)
        labels, inputs = frames, {"video": {"reference": spec.image, **info}}
    else:
        views, frames, info = _frames(ctx, view)
        labels, inputs = frames, {"video": {"reference": spec.image, **info}}
    _same_size(views, labels)
    assert isinstance(spec.scale, KnownEdge)  # the spec's rules
    result = fit_views(views, spec.scale, focal_px=spec.focal_px)
    report = {**joint_report(result, labels), **inputs}
    outputs = {"joint": item_key(view.job_id, view.item.index, JOINT_NAME)}
    if tracking is not None:
        report["tracking"] = tracking.block(labels)
        outputs["tracked_points"] = item_key(view.job_id, view.item.index, TRACKED_NAME)
    ctx.objects.put_json(outputs["joint"], report)
    quality = quality_from_report(report, spec.nominal, spec.tolerance_mm)
    if spec.part_formats:  # the part's solid and drawing, from the joint fit's measurement
        measured = {**report, "quality": quality, "inputs": {"scale": spec.scale.model_dump()}}
        outputs |= put_part_files(ctx, view.job_id, view.item.index, list(spec.part_formats), measured)
    left = [f"{o['name']} left out: {o['reason']}" for o in report["left_out"]]
    if tracking is not None:
        left = tracking.warnings() + left
    camera = report["camera"]
    return ItemResult(
        points=0, point_loss=0.0, dimensions=report["dimensions"], uncertainty=report["uncertainty"],
        warnings=left + report["warnings"], focal_px=camera["focal_px"],
        focal_source="given" if spec.focal_px is not None else "fitted",
        quality=dict(quality) if quality is not None else None,
        given_dimension=spec.scale.edge if spec.scale is not None and spec.scale.kind == "edge" else None,
        joint={"views": report["views"], "left_out": report["left_out"],
               "focal_std_px": camera["focal_std_px"], "distortion_kappa": camera["distortion_kappa"]},
        summary=None if tracking is None else {"tracking": report["tracking"], **inputs},
    ), outputs


def _photos(ctx: WorkerContext, view: ItemView) -> list[View]:
    """The item's views, each photo read where its reference points and decoded."""
    spec = view.item.spec
    assert spec.views is not None
    limit = max_pixels(ctx, spec.max_pixels)
    out, total = [], 0
    for k, v in enumerate(spec.views):
        data, label = read_reference(ctx, v.image, view.tenant)
        image = load_image(data, max_pixels=limit, name=label)
        del data
        total = _within_budget(total, image.shape[0] * image.shape[1], f"views.{k} ({label})")
        out.append(View(image, v.points, v.side_face, v.name or f"view {k + 1}"))
    return out


def _within_budget(total: int, pixels: int, what: str) -> int:
    """The pixels held so far plus one more view's; InputError past `JOINT_MAX_PIXELS` (the API
    checks what it knows of the uploads' sizes, URLs are known only here)."""
    total += pixels
    if total > JOINT_MAX_PIXELS:
        raise InputError(f"{what} brings the views to {total / 1e6:.0f} megapixels together, over a "
                         f"joint fit's {JOINT_MAX_PIXELS / 1e6:.0f}: give fewer or smaller photos")
    return total


def _frames(ctx: WorkerContext, view: ItemView) -> tuple[list[View], list[int], dict[str, Any]]:
    """The video's frames of frame_points as views, their indices, and the video's probe."""
    spec = view.item.spec
    assert spec.frames is not None and spec.frame_points is not None
    with _saved_video(ctx, view) as (path, label, info, frames):
        try:
            _within_budget(0, info.width * info.height * len(frames), f"{len(frames)} frames of "
                           f"{info.width}x{info.height} px")
            views = [View(rgb, spec.frame_points[index], spec.side_face, f"frame {index}")
                     for index, rgb in iter_frames(path, frames)]
        except InputError as exc:  # quote the client's name for the video, not our temp file
            raise InputError(client_message(exc, path, label)) from None
    return views, frames, asdict(info)


@contextmanager
def _saved_video(ctx: WorkerContext, view: ItemView) -> Iterator[tuple[Path, str, VideoInfo, list[int]]]:
    """The item's video in a temporary file while the block runs: its path, the client's name for
    it, its probe and the frames its selection picks (its points_frame, if any, checked against
    the probe first), any refusal in the client's words."""
    spec = view.item.spec
    assert spec.frames is not None
    with tempfile.TemporaryDirectory(prefix="prism-joint-") as tmp:
        path = Path(tmp) / "video"
        with path.open("wb") as dest:
            label = save_input(ctx, view, "front", dest)
        try:
            info = probe_video(path, max_pixels=max_pixels(ctx, spec.max_pixels))
            check_points_frame(spec, info)
            frames = select_frames(path, spec.frames, info, max_frames=ctx.settings.max_frames_per_job)
        except InputError as exc:  # quote the client's name for the video, not our temp file
            raise InputError(client_message(exc, path, label)) from None
        yield path, label, info, frames


def _tracked(ctx: WorkerContext, view: ItemView) -> tuple[list[View], list[int], dict[str, Any], Tracking]:
    """The points of `points_frame` tracked to the selected frames (tracked_points.json stored),
    and the tracked frames whose views differ most as views: their indices, the video's probe
    and the tracking."""
    spec = view.item.spec
    with _saved_video(ctx, view) as (path, label, info, frames):
        tracking = track_item(ctx, view, path, label, frames)
        chosen = joint_frames(tracking, info)
        try:
            views = tracked_views(spec, iter_frames(path, chosen), tracking)
        except InputError as exc:
            raise InputError(client_message(exc, path, label)) from None
    return views, chosen, asdict(info), tracking


def _same_size(views: list[View], labels: list[int] | None) -> None:
    """InputError naming the first view whose image size is not the first view's."""
    h0, w0 = views[0].image.shape[:2]
    for k, v in enumerate(views[1:], start=1):
        h, w = v.image.shape[:2]
        if (h, w) != (h0, w0):
            where = f" (views[{k}])" if labels is None else ""
            raise InputError(f"{v.name}{where} is {w}x{h} px, {views[0].name} {w0}x{h0} px: the "
                             "views of a joint fit must come from one camera at one image size")

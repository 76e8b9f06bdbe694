"""Planning and the item steps' inputs and artifacts (prism_worker.steps, inputs, artifacts) on
in-memory fakes; the engine's own stages are tested in tests/engine and end to end in
tests/service."""

from __future__ import annotations

import math

import numpy as np
import pytest
from prism_common.records import State
from prism_common.references import ReferenceError

from prism_worker import artifacts, inputs, lifecycle, steps
from prismcore import InputError

from .conftest import SPEC, Fakes


@pytest.mark.parametrize(("per_face", "in_flight", "n_items"), [
    (4, 2, 1), (4, 2, 2), (4, 2, 50), (8, 3, 2), (8, 3, 3), (1, 4, 1), (16, 4, 100), (5, 1, 7)])
def test_a_job_keeps_about_tiles_per_face_tile_tasks_per_face_in_flight(
        fakes: Fakes, per_face: int, in_flight: int, n_items: int) -> None:
    ctx = fakes.with_settings(tiles_per_face=per_face, items_in_flight_per_job=in_flight).ctx
    got = steps.tiles_per_face(ctx, n_items)
    assert got == math.ceil(per_face / min(n_items, in_flight))
    assert got * min(n_items, in_flight) >= per_face  # never fewer in flight than asked


@pytest.mark.parametrize(("spec_limit", "service_limit"), [(10**6, 4 * 10**6), (8 * 10**6, 2 * 10**6)])
def test_the_stricter_pixel_limit_applies(fakes: Fakes, spec_limit: int, service_limit: int) -> None:
    ctx = fakes.with_settings(max_pixels=service_limit).ctx
    assert steps.max_pixels(ctx, spec_limit) == min(spec_limit, service_limit)


@pytest.mark.parametrize("shape", [(1, 1), (3, 8), (5, 13), (64, 100), (7, 1)])
def test_a_tile_round_trips_bit_for_bit(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    masks = rng.random(shape) < 0.5, rng.random(shape) < 0.1
    back = artifacts.unpack_tile(artifacts.pack_tile(*masks))
    for original, read in zip(masks, back, strict=True):
        assert read.dtype == bool and np.array_equal(read, original)


def test_keys_are_deterministic_and_refuse_unsafe_segments() -> None:
    job = "a" * 32
    assert artifacts.item_key(job, 3, "plan.json") == f"jobs/{job}/items/3/plan.json"
    assert artifacts.tile_key(job, 0, "front", 0, 10) == f"jobs/{job}/items/0/tiles/front-0-10.npz"
    assert artifacts.frame_key(job, 1, 7, "frame.png").startswith(f"jobs/{job}/items/1/frame_")
    for bad in ("..", "a/b", ""):
        with pytest.raises(ValueError, match="unsafe object key segment"):
            artifacts.item_key(bad, 0, "x")


def _view(fakes: Fakes, image: str):
    job_id = fakes.job(items=1, state=State.running, spec=SPEC.model_copy(update={"image": image}))
    view = fakes.store.get_item(job_id, 0)
    assert view is not None
    return view


def test_an_upload_is_copied_into_the_job_once_under_its_name(fakes: Fakes) -> None:
    view = _view(fakes, fakes.upload(b"photo bytes", name="my box.jpg"))
    key, label = inputs.copy_input(fakes.ctx, view, "front")
    assert key == artifacts.item_key(view.job_id, 0, "front") and label == "my box.jpg"
    assert fakes.objects.get_bytes(key) == b"photo bytes"
    upload_key = fakes.store.get_upload(view.item.spec.image.removeprefix("upload:"))["key"]
    fakes.objects.delete_keys([upload_key])  # a re-run reads the copy, not the upload
    assert inputs.copy_input(fakes.ctx, view, "front") == (key, "my box.jpg")


@pytest.mark.parametrize(("case", "message"), [
    ("missing object", "no object 'upload:"), ("other tenant", "no upload '"),
    ("too large", "over the limit of 5"), ("bucket not readable", "is not one the service may read")])
def test_inputs_the_service_may_not_or_cannot_read_are_refused(fakes: Fakes, case: str, message: str) -> None:
    ctx = fakes.with_settings(upload_max_bytes=5).ctx if case == "too large" else fakes.ctx
    if case == "bucket not readable":
        ref = "s3://secrets/key.jpg"
    else:
        ref = fakes.upload(b"123456" if case == "too large" else b"1",
                           tenant="other" if case == "other tenant" else "acme")
    if case == "missing object":
        fakes.objects.delete_keys(fakes.objects.list_keys("uploads/"))
    view = _view(fakes, ref)
    with pytest.raises(ReferenceError, match=message):
        inputs.copy_input(ctx, view, "front")
    assert fakes.objects.list_keys("jobs/") == []


def test_a_readable_bucket_is_read_where_the_reference_points(fakes: Fakes) -> None:
    ctx = fakes.with_settings(readable_buckets=["inputs"]).ctx
    fakes.objects.client.other["inputs"] = {"shots/box.jpg": b"from the inputs bucket"}
    view = _view(fakes, "s3://inputs/shots/box.jpg")
    assert inputs.read_input(ctx, view, "front") == (b"from the inputs bucket", "s3://inputs/shots/box.jpg")
    assert fakes.objects.list_keys("jobs/") == []  # read, not copied


@pytest.mark.parametrize("step", ["plan", "whole"])
def test_a_file_that_is_not_a_photo_fails_its_item_naming_the_file(fakes: Fakes, step: str) -> None:
    view = _view(fakes, fakes.upload(b"%PDF-1.7 not a photo", name="invoice.pdf"))
    with pytest.raises(InputError, match=r"invoice\.pdf") as caught:
        if step == "plan":
            steps.plan_item(fakes.ctx, view)
        else:
            steps.scan_whole_item(fakes.ctx, view)
    assert not fakes.objects.exists(artifacts.item_key(view.job_id, 0, "plan.json"))
    lifecycle.fail_and_complete(fakes.ctx, view.job_id, 0, str(caught.value), maybe_repeat=False)
    job = fakes.store.get(view.job_id)
    assert job.state == State.failed and "invoice.pdf" in job.items[0].error


def test_finishing_before_every_tile_is_stored_is_retried(fakes: Fakes) -> None:
    view = _view(fakes, fakes.upload(b"x"))
    with pytest.raises(steps.TilesMissingError, match="not stored yet"):
        steps._tile_bytes(fakes.objects, artifacts.tile_key(view.job_id, 0, "front", 0, 10), 0)

"""A video item's frames counted and summarised into the item (prism_worker.video) on fakes."""

from __future__ import annotations

import json

import pytest
from prism_common.records import FrameRecord, ItemResult, State

from prism_worker import artifacts, lifecycle, video

from .conftest import SPEC, Fakes

VIDEO = SPEC.model_validate({**SPEC.model_dump(), "frames": {"indices": [0]}})
FRAMES = [0, 5, 10, 15]


def _video_job(fakes: Fakes) -> str:
    job_id = fakes.job(items=1, spec=VIDEO)
    lifecycle.start_job(fakes.ctx, job_id, maybe_repeat=False)
    fakes.sent.take()
    fakes.objects.put_json(artifacts.item_key(job_id, 0, video.FRAMES_NAME),
                           {"frames": FRAMES, "video": {"fps": 5.0, "frame_count": 20}})
    return job_id


def _measured(width: float) -> FrameRecord:
    return FrameRecord(index=0, state=State.succeeded, outputs={"csv": "x"}, result=ItemResult(
        points=100, dimensions={"width": width, "height": 20.0, "depth": 30.0, "unit": "mm"},
        point_loss=0.1, warnings=[]))


@pytest.mark.parametrize("failed", [[], [5], [0, 15], [0, 5, 10]])
def test_the_last_frame_summarises_the_item_with_the_median(fakes: Fakes, failed: list[int]) -> None:
    job_id = _video_job(fakes)
    widths = {0: 10.0, 5: 12.0, 10: 11.0, 15: 100.0}
    for n in FRAMES:
        assert fakes.store.get(job_id).items[0].state == State.queued  # not before the last
        record = (FrameRecord(index=n, state=State.failed, error=f"blurred {n}") if n in failed
                  else _measured(widths[n]).model_copy(update={"index": n}))
        fakes.store.put_frame(job_id, 0, record)
        video.frame_finished(fakes.ctx, job_id, 0, n, maybe_repeat=False)
    job = fakes.store.get(job_id)
    item = job.items[0]
    measured = sorted(w for n, w in widths.items() if n not in failed)
    mid = len(measured) // 2
    median = measured[mid] if len(measured) % 2 else (measured[mid - 1] + measured[mid]) / 2
    assert (job.state, item.state) == (State.succeeded, State.succeeded)
    assert item.result.dimensions["width"] == pytest.approx(median)
    assert item.result.points == 100 * len(measured)
    assert item.result.warnings == ([f"{len(failed)} of 4 frames could not be measured"] if failed else [])
    summary = json.loads(fakes.objects.get_bytes(item.outputs["summary"]))
    assert summary["frames"] == {"selected": 4, "measured": len(measured), "failed": len(failed)}
    assert summary["video"]["reference"] == VIDEO.image


def test_an_item_none_of_whose_frames_measured_fails_with_the_first_error(fakes: Fakes) -> None:
    job_id = _video_job(fakes)
    for n in FRAMES:
        video.frame_failed(fakes.ctx, job_id, 0, n, f"no box in frame {n}")
        video.frame_failed(fakes.ctx, job_id, 0, n, "a later failure does not overwrite")
        video.frame_finished(fakes.ctx, job_id, 0, n, maybe_repeat=True)
    job = fakes.store.get(job_id)
    assert job.state == State.failed
    assert job.items[0].error == "no frame could be measured (frame 0: no box in frame 0)"
    assert [f.error for f in job.items[0].frames] == [f"no box in frame {n}" for n in FRAMES]


def test_a_frame_counted_twice_does_not_finish_the_item_early(fakes: Fakes) -> None:
    job_id = _video_job(fakes)
    for _ in range(4):
        fakes.store.put_frame(job_id, 0, _measured(10.0))
        video.frame_finished(fakes.ctx, job_id, 0, 0, maybe_repeat=True)
    assert fakes.store.get(job_id).items[0].state == State.queued
    assert fakes.store.state(job_id) == State.running

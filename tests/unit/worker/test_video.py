"""A video item's frames counted and summarised into the item (prism_worker.video) on fakes."""

from __future__ import annotations

import json

import pytest
from prism_common.queue import TASK_SCAN_FRAME, TASK_SPLIT_VIDEO
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


# -- the split in parts ---------------------------------------------------------------------------

SPLIT_FRAMES = 6


class _Ticking:
    """A clock that moves 1 s at every reading: a part's time runs out after a few frames."""

    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        self.now += 1.0
        return self.now


@pytest.fixture(scope="module")
def clip_bytes(tmp_path_factory) -> bytes:
    from prismsynth import Box, render_clip, write_video
    path = tmp_path_factory.mktemp("clip") / "clip.avi"
    write_video((s.image for s in render_clip(Box(120.0, 80.0, 60.0), SPLIT_FRAMES, image_size=(160, 128))),
                path)
    return path.read_bytes()


def _split_job(fakes: Fakes, clip: bytes) -> tuple[Fakes, str]:
    """A running video job (focal given: frames are sent as they are stored) on a clock that
    ends a part every other reading."""
    from dataclasses import replace
    spec = SPEC.model_validate({**SPEC.model_dump(), "image": fakes.upload(clip, name="clip.avi"),
                                "frames": {}, "focal_px": 1400.0})
    fast = fakes.with_settings(video_split_part_s=1.5)
    fast = replace(fast, ctx=replace(fast.ctx, clock=_Ticking(fakes.clock.now)))
    job_id = fakes.job(items=1, spec=spec, state=State.running)
    return fast, job_id


def _run_part(fakes: Fakes, job_id: str, part: int) -> list[tuple[str, tuple]]:
    view = fakes.store.get_item(job_id, 0)
    assert view is not None
    video.split_video(fakes.ctx, view, part)
    return fakes.sent.take()


def test_a_split_in_parts_sends_every_frame_once_and_each_part_once(fakes: Fakes, clip_bytes: bytes) -> None:
    fast, job_id = _split_job(fakes, clip_bytes)
    scans, part, parts = [], 0, []
    while True:
        sent = _run_part(fast, job_id, part)
        scans += [args[2] for name, args in sent if name == TASK_SCAN_FRAME]
        nxt = [args[2] for name, args in sent if name == TASK_SPLIT_VIDEO]
        if not nxt:
            break
        parts.append(nxt[0])
        if part:  # a redelivered copy of a later part that handed on: the next has the rest
            assert _run_part(fast, job_id, part) == []
        part = nxt[0]
    assert scans == list(range(SPLIT_FRAMES)) and len(parts) >= 2, (scans, parts)


def test_a_lost_part_is_taken_up_when_the_split_restarts(fakes: Fakes, clip_bytes: bytes) -> None:
    fast, job_id = _split_job(fakes, clip_bytes)
    first = _run_part(fast, job_id, 0)
    [(_, (_, _, lost))] = [s for s in first if s[0] == TASK_SPLIT_VIDEO]  # never delivered
    # The watchdog restarts the stalled job: plan_item splits from part 0 again, which goes on
    # from the part that was lost (its frames, not part 0's again).
    again = _run_part(fast, job_id, 0)
    done = [args[2] for name, args in first if name == TASK_SCAN_FRAME]
    resumed = [args[2] for name, args in again if name == TASK_SCAN_FRAME]
    assert resumed and resumed[0] == done[-1] + 1, (done, resumed)
    # The part that was lost, had it run after all, hands on no second time.
    assert [s for s in _run_part(fast, job_id, lost) if s[0] == TASK_SPLIT_VIDEO] == []

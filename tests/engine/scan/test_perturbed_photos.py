"""A measurement must not depend on the machine beyond noise.

Each photo is changed as another machine or another decoder might change it (one grey level up,
a JPEG re-encode at quality 95, a 0.1 px shift) and measured again from the same clicks: the
decision (measured or refused) must be the same, and each dimension must move by less than the
1-sigma the first measurement stated, unless the measurement says it may be wrong: a warning (the
fitted box's corners several px from the clicks, edges not found, the clicks used instead of the
edges) marks a fit whose edges sit on printed borders or background and may take another border
after a 0.1 px change. On the real video that is 5 of the 12 frames; such a frame moved by up to
3.4 sigma (frame 105's depth, 203 -> 252 mm), which its warning tells.
The photos: the sample (`samples/box.jpg`, its clicks in `samples/job.json`), photo-like
renders with clicks off by up to 3 px and no focal length, and the hand-marked frames of OpenCV's
real cookie-box video.

The zero-click search (`prismcore.locate.search`) decides on regions that close or leak on one grey
level. It pools its faces over two samplings of the photo and says when a box rests on a face
only one of them found (`Found.stable`, and a warning); a decision that flips under these changes
must have said so on one side or the other. Over seeds 0-143 (432 scene-perturbations) the
decision flipped 15 times (28 before the pooling), none unflagged: held as rates below.
"""

from __future__ import annotations

import importlib.util
import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore import InputError, ScanSpec, plan_scan
from prismcore.io.images import load_image
from prismcore.locate.search import Found, find_points
from prismsynth import photo_like_scene
from prismsynth.scenes import clutter_scene

ROOT = Path(__file__).resolve().parents[3]
pytestmark = pytest.mark.slow  # about 30 photos, each fitted four times


def grey_plus_one(image: np.ndarray) -> np.ndarray:
    return np.clip(image.astype(np.int16) + 1, 0, 255).astype(np.uint8)


def jpeg_again(image: np.ndarray) -> np.ndarray:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    return cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def shifted(image: np.ndarray) -> np.ndarray:
    move = np.float32([[1, 0, 0.1], [0, 1, 0.1]])
    return cv2.warpAffine(image, move, (image.shape[1], image.shape[0]), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)


PERTURBATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "grey+1": grey_plus_one, "jpeg-q95": jpeg_again, "shift-0.1px": shifted}


def _sample() -> list[tuple[str, ScanSpec, np.ndarray]]:
    job = json.loads((ROOT / "samples" / "job.json").read_text())
    image = load_image((ROOT / "samples" / job["image"]).read_bytes())
    return [("sample", ScanSpec.model_validate(job), image)]


def _photo_like() -> list[tuple[str, ScanSpec, np.ndarray]]:
    out = []
    for seed in range(8):
        p = photo_like_scene(seed)
        spec = ScanSpec(image="photo.jpg", points=[list(map(float, xy)) for xy in p.click_list()],
                        scale={"kind": "edge", "edge": p.known_edge, "length_mm": p.known_length_mm})
        out.append((f"photo-like-{seed}", spec, p.image))
    return out


def _real_video() -> list[tuple[str, ScanSpec, np.ndarray]]:
    path = ROOT / "benchmarks" / "real_video_data.py"
    loader = importlib.util.spec_from_file_location("real_video_data", path)
    assert loader is not None and loader.loader is not None
    rvd = importlib.util.module_from_spec(loader)
    loader.loader.exec_module(rvd)
    marked = [f for f in rvd.load_marks()["frames"] if f["side"] == "right"]
    images = rvd.read_frames(rvd.video_path(), [f["index"] for f in marked])
    return [(f"video-{f['index']}", ScanSpec.model_validate({
        "image": "frame.png", "points": rvd.points_of(f), "side_face": f["side"],
        "scale": {"kind": "edge", "edge": "width", "length_mm": rvd.truth_mm(f)["width"]}}),
        images[f["index"]]) for f in marked]


def _measure(spec: ScanSpec, image: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]] | str:
    """(width, height, depth), their 1-sigma and the warnings; or the refusal."""
    try:
        plan = plan_scan(spec, image)
    except InputError as exc:
        return str(exc)
    dims = plan.dimensions
    assert dims.uncertainty is not None
    return np.array([dims.width, dims.height, dims.depth]), np.array(dims.uncertainty), list(plan.warnings)


PHOTOS = {"sample": _sample, "photo-like": _photo_like, "real-video": _real_video}
# Where a move past sigma is allowed when the measurement warned that its fitted box sits px from
# the clicks: on the real video's printed box the edges take another border after a 0.1 px change
# (5 of its 12 frames). The sample and the photo-like renders must hold whatever they warn (their
# clicks are off by up to 3 px by design, so they warn too).
FLAG_EXCUSES = {"sample": False, "photo-like": False, "real-video": True}
HELD_AT_LEAST = {"sample": 3, "photo-like": 24, "real-video": 24}  # of 3, 24, 36 (29 here)
_DOUBT = ("lie more than", "the clicks were used", "edges not found near the clicks")


@pytest.mark.parametrize("kind", PHOTOS)
def test_a_slight_change_of_the_photo_keeps_the_decision_and_the_dimensions_within_sigma(kind: str) -> None:
    moved, held = [], 0
    for name, spec, image in PHOTOS[kind]():
        first = _measure(spec, image)
        for how, perturb in PERTURBATIONS.items():
            again = _measure(spec, perturb(image))
            if isinstance(first, str) or isinstance(again, str):
                assert isinstance(first, str) and isinstance(again, str), (name, how, first, again)
                continue
            (dims, sigma, warnings), (dims2, _, warnings2) = first, again
            if not np.any(np.abs(dims2 - dims) > sigma + 1e-9 * dims):  # the known edge's sigma is 0
                held += 1
                continue
            flagged = all(any(d in w for w in ws for d in _DOUBT)
                          for ws in (warnings, warnings2))
            if not (FLAG_EXCUSES[kind] and flagged):
                moved.append((name, how, np.round(dims, 2).tolist(), np.round(dims2, 2).tolist(),
                              np.round(sigma, 2).tolist()))
    assert moved == []
    assert held >= HELD_AT_LEAST[kind]  # so the test is not vacuous


SEARCH_SEEDS = range(60, 120)  # the accuracy tests' seeds are 0-39


def _flagged(found: Found) -> bool:
    """The result says its decision may not hold: unstable, or accepted with a warning."""
    return not found.stable or (found.ok and bool(found.warnings))


def test_the_search_decision_holds_under_a_slight_change_or_says_it_may_not() -> None:
    flips, unflagged = [], []
    for seed in SEARCH_SEEDS:
        image = clutter_scene(seed).image
        first = find_points(image)
        for how, perturb in PERTURBATIONS.items():
            again = find_points(perturb(image))
            if again.ok == first.ok:
                continue
            flips.append((seed, how))
            if not (_flagged(first) or _flagged(again)):
                unflagged.append((seed, how, first.reason, again.reason))
    cases = len(SEARCH_SEEDS) * len(PERTURBATIONS)
    # Measured over seeds 0-143: 15 flips (3.5 %), none unflagged.
    assert len(flips) <= 0.07 * cases, flips
    assert len(unflagged) <= 0.02 * cases, unflagged

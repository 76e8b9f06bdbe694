"""Issue 20, items 1-2: several photos of one box measured as one box (`prismcore.multiview.joint.fit_views`).

Oracle: `prismsynth.photo_like_views`, photo-like renders of ONE box from three viewpoints by one
phone (focal length unknown to the engine, lens distortion, rounded edges, JPEG, clicks 0-3 px
off, one known edge). Asserted over a fixed set of seeds, on the two dimensions the known edge
does not set: the median and worst error and how often the stated 2-sigma covers the truth, with
bounds set from what was measured (see each bound's comment; `benchmarks/joint_fit.py` prints the
figures over more cases beside the single-view ones). A view whose points mark a different box is
named and left out, and the result is what the other views measure.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from prismcore import InputError
from prismcore.multiview.joint import CLICK_WARN_PX, JointResult, View, fit_views
from prismcore.multiview.report import joint_report
from prismcore.spec import KnownEdge, MmPerPx
from prismsynth import PhotoLikeScene, photo_like_views

SEEDS = tuple(range(8))
DIMENSIONS = ("width", "height", "depth")
pytestmark = pytest.mark.slow  # eight boxes, three photo-like renders and a joint fit each


def _scale(p: PhotoLikeScene) -> KnownEdge:
    return KnownEdge(edge=p.known_edge, length_mm=p.known_length_mm)  # type: ignore[arg-type]


def _views(scenes: list[PhotoLikeScene]) -> list[View]:
    return [View(q.image, q.click_list(), name=f"view {i + 1}") for i, q in enumerate(scenes)]


@pytest.fixture(scope="module")
def cases() -> list[tuple[list[PhotoLikeScene], JointResult]]:
    out = []
    for seed in SEEDS:
        scenes = photo_like_views(seed, 3)
        out.append((scenes, fit_views(_views(scenes), _scale(scenes[0]))))
    return out


@pytest.fixture(scope="module")
def errors(cases) -> tuple[np.ndarray, np.ndarray]:
    """Relative errors and relative 1-sigma of the dimensions the known edge does not set."""
    errs, sigmas = [], []
    for scenes, result in cases:
        p, d = scenes[0], result.dimensions
        assert d.uncertainty is not None
        for name, sigma in zip(DIMENSIONS, d.uncertainty, strict=True):
            if name == p.known_edge:
                continue
            true = float(getattr(p.box, f"{name}_mm"))
            errs.append(getattr(d, name) / true - 1)
            sigmas.append(sigma / true)
    return np.array(errs), np.array(sigmas)


def test_the_known_edge_is_kept_and_the_camera_is_found(cases) -> None:
    for scenes, result in cases:
        p = scenes[0]
        assert getattr(result.dimensions, p.known_edge) == pytest.approx(p.known_length_mm)
        assert result.focal_std_px is not None
        assert result.focal_px == pytest.approx(p.camera_matrix[0, 0], rel=0.05)
        assert len(result.views) + len(result.left_out) == 3


# Issue 20's target: 0.5 %. Seeds 0-7 measured 0.34 % (each view alone: 0.57 %); over seeds 0-19
# (benchmarks/joint_fit.py) 0.37 % (0.50 % before each view was weighed by its own noise and lines
# off the joint box were left out), over the held-out seeds 20-59 0.50 % (was 0.58 %) and 100-129
# 0.62 % (was 0.54 %: on renders the change is within their seed-to-seed spread; it is the real
# video it fixes, test_the_real_video_as_one_box).
def test_median_error(errors) -> None:
    err, _ = errors
    assert np.median(np.abs(err)) <= 0.005, np.round(err * 100, 2)


# Issue 20's target: 1.5 %. NOT MET: seeds 0-7 measured 1.72 % (seed 0: a 47 mm known depth whose
# rounded edges, 0.9 mm, the shading does not resolve, so no silhouette is corrected; the three
# views share that bias; each view alone reaches 2.01 %); over seeds 0-19 2.00 % (was 2.48 %; 5.48 %
# alone), over seeds 20-59 3.24 % (was 4.07 %; a 55 x 50 mm box with 2.3 mm edges every view alone
# gets 3-11 % wrong), over seeds 100-129 2.35 % (was 1.93 %). The bound holds what is reached with
# a margin, so a loss of accuracy fails here.
def test_worst_error(errors) -> None:
    err, _ = errors
    assert np.abs(err).max() <= 0.02, np.round(err * 100, 2)


# Issue 20's target: the stated 2-sigma covers the truth in at least 90 % of cases. Seeds 0-7: 16 of
# 16; seeds 0-19: 40 of 40; seeds 20-59: 77 of 80. The sigma includes what the shared views cannot
# average away (the rounded folds' place on their shading ramps, the lens and the radius), so it is
# wider than the scatter alone: its median is 0.91 % here (1.12 % over seeds 0-19).
def test_two_sigma_covers_the_truth(errors) -> None:
    err, sigma = errors
    covered = np.abs(err) <= 2 * sigma
    assert covered.mean() >= 0.9, np.round(np.abs(err) / sigma, 2)
    assert np.median(sigma) <= 0.015, np.round(sigma * 100, 2)  # and it says something


@pytest.fixture(scope="module")
def clean() -> list[PhotoLikeScene]:
    return photo_like_views(2, 3)


def _deeper(p: PhotoLikeScene, factor: float) -> list[tuple[float, float]]:
    """The clicks with the second face's far corners pulled out along the depth: a deeper box."""
    c = {k: np.asarray(v) for k, v in p.clicks.items()}
    c["p5"] = c["p4"] + factor * (c["p5"] - c["p4"])
    c["p7"] = c["p3"] + factor * (c["p7"] - c["p3"])
    return [(float(c[f"p{k}"][0]), float(c[f"p{k}"][1])) for k in range(1, 8)]


def test_a_view_with_wrong_clicks_is_named_and_left_out(clean) -> None:
    views = _views(clean)
    views[1] = View(clean[1].image, _deeper(clean[1], 1.15), name="wrong.jpg")
    result = fit_views(views, _scale(clean[0]))
    assert [o.name for o in result.left_out] == ["wrong.jpg"]
    assert "disagrees with the other views beyond its noise" in result.left_out[0].reason
    assert [v.name for v in result.views] == ["view 1", "view 3"]
    box = clean[0].box
    for name in DIMENSIONS:
        assert getattr(result.dimensions, name) == pytest.approx(getattr(box, f"{name}_mm"), rel=0.01)
    assert result.left_out[0].index == 1


def test_consistent_views_are_all_kept(clean) -> None:
    result = fit_views(_views(clean), _scale(clean[0]))
    assert result.left_out == ()
    assert all(v.disagreement is not None for v in result.views)
    assert all(v.click_rms_px < 4.0 for v in result.views)


def test_refusals(clean) -> None:
    p = clean[0]
    with pytest.raises(InputError, match="no views"):
        fit_views([], _scale(p))
    with pytest.raises(InputError, match="known edge"):
        fit_views(_views(clean), MmPerPx(front=0.5))  # type: ignore[arg-type]
    small = View(p.image[:-10], p.click_list(), name="cropped")
    with pytest.raises(InputError, match="one image size"):
        fit_views([*_views(clean)[:2], small], _scale(p))


def test_edge_lines_the_clicks_disagree_with_can_be_left_out(clean) -> None:
    kept = fit_views(_views(clean), _scale(clean[0]), edge_agree_px=50.0)
    assert not any("refined edge" in w for w in kept.warnings)
    strict = fit_views(_views(clean), _scale(clean[0]), edge_agree_px=0.01)  # no line is that close
    assert len([w for w in strict.warnings if "refined edge(s)" in w]) == 3
    assert all(v.line_rms_px == 0.0 for v in strict.views)  # the clicks alone
    box = clean[0].box
    for name in DIMENSIONS:
        assert getattr(strict.dimensions, name) == pytest.approx(getattr(box, f"{name}_mm"), rel=0.03)


def test_an_edge_line_on_another_feature_is_left_out(clean, monkeypatch) -> None:
    """A view's refined edge moved 6 px off the box (as onto a printed border parallel to it) lies
    off the box the other views share: it is left out and the box is what the clean views give."""
    import prismcore.multiview.joint as joint

    prepare = joint._prepare

    def moved(k, view, *args, **kwargs):  # type: ignore[no-untyped-def]
        got = prepare(k, view, *args, **kwargs)
        if k != 1:
            return got
        lines = list(got.front.lines)
        assert lines[0] is not None
        lines[0] = lines[0] + np.array([0.0, 0.0, 6.0])  # the front's top edge, 6 px off
        return replace(got, front=replace(got.front, lines=tuple(lines)))

    monkeypatch.setattr(joint, "_prepare", moved)
    result = fit_views(_views(clean), _scale(clean[0]))
    assert result.views[1].lines_left_out >= 1
    assert result.lines_left_out == sum(v.lines_left_out for v in result.views)
    # joint.json (the CLI's, the service's) says which view lost them
    reported = [v["lines_left_out"] for v in joint_report(result)["views"]]
    assert reported == [v.lines_left_out for v in result.views]
    box = clean[0].box
    for name in DIMENSIONS:
        assert getattr(result.dimensions, name) == pytest.approx(getattr(box, f"{name}_mm"), rel=0.01)


def test_a_view_whose_edges_all_moved_is_warned_about_by_its_clicks(clean, monkeypatch) -> None:
    """Every edge of view 2 moved 6 px outward: its pose follows them (a nearer box), so its
    clicks end up far from the shared box; it is named in a warning, the clean views are not."""
    import prismcore.multiview.joint as joint

    prepare = joint._prepare

    def moved(k, view, *args, **kwargs):  # type: ignore[no-untyped-def]
        got = prepare(k, view, *args, **kwargs)
        if k != 1:
            return got
        faces = {name: replace(face, lines=tuple(None if line is None else line + np.array([0.0, 0.0, 6.0])
                                                 for line in face.lines))
                 for name, face in (("front", got.front), ("side", got.side))}
        return replace(got, **faces)

    monkeypatch.setattr(joint, "_prepare", moved)
    result = fit_views(_views(clean), _scale(clean[0]))
    warned = [w for w in result.warnings if "its clicks lie" in w]
    assert len(warned) == 1 and warned[0].startswith("view 2: its clicks lie "), result.warnings
    assert result.views[1].click_rms_px > CLICK_WARN_PX


def test_clean_views_carry_no_click_warning(cases) -> None:
    for _, result in cases:
        assert not any("its clicks lie" in w for w in result.warnings), result.warnings


# A subtler wrong view than 15 %: its lines are judged against the shared box before the views are
# (an edge far off that box is left out first), so a wrong view must still be found by its
# disagreement. Measured with the lines judged and without (before 1c272f7): 6 % and 8 % deeper
# left out either way on seeds 2 and 5 (and 4 % on seed 5 now), the box within 0.35 %.
@pytest.mark.parametrize("seed", [2, 5])
@pytest.mark.parametrize("factor", [1.06, 1.08])
def test_a_view_marking_a_few_percent_deeper_box_is_left_out(seed: int, factor: float) -> None:
    scenes = photo_like_views(seed, 4)
    views = _views(scenes)
    views[1] = View(scenes[1].image, _deeper(scenes[1], factor), name="wrong.jpg")
    result = fit_views(views, _scale(scenes[0]))
    assert [o.name for o in result.left_out] == ["wrong.jpg"]
    box = scenes[0].box
    for name in DIMENSIONS:
        assert getattr(result.dimensions, name) == pytest.approx(getattr(box, f"{name}_mm"), rel=0.01)


def _video_module():  # type: ignore[no-untyped-def]
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "benchmarks" / "real_video_data.py"
    spec = importlib.util.spec_from_file_location("real_video_data", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# Issue 20's target on the real cookie-box video (12 hand-marked frames, width known, no focal): the
# joint fit within 2 % on height and depth. Measured +1.7 % / +1.4 % (it was +4.1 % / +5.0 % while
# every frame's lines weighed 0.3 px and its clicks 5 px whatever they showed: frames whose edges
# include a printed border kept them with their clicks 4-8 px off); the bound keeps a margin.
def test_the_real_video_as_one_box() -> None:
    rvd = _video_module()
    frames = rvd.load_marks()["frames"]
    try:
        path = rvd.video_path()
    except FileNotFoundError as exc:  # fail, not skip: the acceptance figure must not vanish silently
        pytest.fail(f"the real box video is missing: {exc}")
    images = rvd.read_frames(path, [f["index"] for f in frames])
    truth = rvd.truth_mm(frames[0])
    views = [View(images[f["index"]], rvd.points_of(f), f["side"], f"frame {f['index']}") for f in frames]
    result = fit_views(views, KnownEdge(edge="width", length_mm=truth["width"]))
    d = result.dimensions
    assert d.uncertainty is not None
    for k, name in ((1, "height"), (2, "depth")):
        error = getattr(d, name) - truth[name]
        assert abs(error) <= 0.025 * truth[name], (name, getattr(d, name))
        assert abs(error) <= 2 * d.uncertainty[k], (name, getattr(d, name), d.uncertainty[k])

"""Seven points marked on one frame of a hand-held video, carried to the other frames by tracking.

A person marks the box's seven reference points (P1..P7, the engine's order) on one frame; the
points of every other selected frame follow from the box's own motion. By default
(`TrackerSettings.motion == "box"`) the box moves as one rigid body: the marked points fix a box
model, features on every face the camera sees (the lid too) are placed on it, and each frame's
camera pose is fitted to all of them at once (`prismcore.video.box_motion`), the points being the
box's corners projected. With `motion == "faces"` each marked face moves on its own:

* features (`cv2.goodFeaturesToTrack`) are taken inside each face's quadrilateral (the front,
  and the second face the points mark), a few px inside its sides so that the background past
  a silhouette does not move them;
* every frame between the selected frames is tracked (small steps): pyramidal Lucas-Kanade
  from one frame to the next, each feature checked forward and backward (tracked back, it must
  land within `TrackerSettings.fb_max_px` of where it started);
* each face's motion is re-estimated robustly from its surviving features, a RANSAC homography
  (`cv2.findHomography`) from the frame the points were last fixed on (the anchor) to this one,
  and the face's points are moved with it (the shared corner with the front's);
* on the selected frames only, the points are refined on the box's edges as clicks are, by the
  engine's own plan (`prismcore.video.track_refine.box_refiner`, through
  `prismcore.scan.pipeline.plan_scan`: edges fitted to sub-pixel lines, the
  box fitted to them, its fit guard), and the tracker takes the refined points as its new anchor.

A frame whose track is lost (too few inliers on the front, forward-backward errors too large) or
whose box no longer fits (the plan's fit guard refuses it) is named with the reason and left out;
the track is then picked up from the last good frame, with a wider search (larger window, more
pyramid levels) straight to each later frame, for up to `TrackerSettings.max_gap` frames (no
feature surviving at all is such a loss: a hand passing over the box). A cut to another scene (a
large change of the grey-level histogram from one frame to the next) ends the track at once, and
a track not found again within `max_gap` frames ends too: every later frame is left out with the
reason.

Frames before the marked one are tracked backwards from it (the caller's frames are kept, in
grey, until the marked one is reached). Pure functions over arrays: no I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from prismcore.errors import InputError
from prismcore.geometry.faces import SideFace, clicked_quads, resolve_side_face, shared_edges
from prismcore.spec import ReferencePoints
from prismcore.video.box_motion import BoxTracker
from prismcore.video.track_parts import DEFAULT_SETTINGS, TrackerSettings
from prismcore.video.track_parts import Face as _Face
from prismcore.video.track_parts import State as _State
from prismcore.video.track_parts import Step as _Step
from prismcore.video.track_parts import features as _features
from prismcore.video.track_parts import grey as _grey
from prismcore.video.track_parts import histogram as _histogram
from prismcore.video.track_parts import inset_mask as _inset_mask
from prismcore.video.track_parts import lk as _lk

__all__ = [
    "POINT_NAMES",
    "Refiner",
    "TrackQuality",
    "TrackedFrame",
    "TrackerSettings",
    "track_points",
]

POINT_NAMES: tuple[str, ...] = tuple(ReferencePoints.model_fields)  # the spec's p1..p7
_FRONT = (0, 1, 2, 5)  # P1, P2, P3, P6: the front face's corners, in its quad's order
_SIDE_ONLY = (4, 6)  # P5, P7: the second face's far corners (P4 is a front corner)


def _fold_corners(side_face: SideFace) -> list[int]:
    """The two front corners (indices into P1..P7) on the edge the front shares with the second face."""
    edge = shared_edges(side_face)[0]
    return [_FRONT[edge], _FRONT[(edge + 1) % 4]]



@dataclass(frozen=True)
class TrackQuality:
    """How well one frame's points were tracked.

    inliers : int
        The features that follow the box: the faces' homography inliers together (front + second
        face), or with the box's motion ("box") those on every face the pose was fitted to.
    inliers_front, inliers_side : int
        Of them, those on the front and on the second face.
    fb_error_px : float
        Median forward-backward error of the features kept, px (0 on the marked frame).
    confidence : float
        0..1: more inliers, smaller forward-backward errors and a small refinement shift are
        more sure (on the marked frame: its features and how far the refinement moved the marks).
    refine_shift_px : float or None
        Largest move of a point by the refinement on the edges, px (None: not refined).
    steps : int
        Frames tracked since the marked frame (0 for it).
    """

    inliers: int
    inliers_front: int
    inliers_side: int
    fb_error_px: float
    confidence: float
    refine_shift_px: float | None = None
    steps: int = 0

    def as_json(self) -> dict[str, Any]:
        """JSON-ready, rounded."""
        return {"inliers": self.inliers, "inliers_front": self.inliers_front,
                "inliers_side": self.inliers_side, "fb_error_px": round(self.fb_error_px, 3),
                "confidence": round(self.confidence, 3),
                "refine_shift_px": None if self.refine_shift_px is None else round(self.refine_shift_px, 3),
                "steps": self.steps}


@dataclass(frozen=True)
class TrackedFrame:
    """One reported frame: its seven points and their quality, or the reason it is left out.

    index : int
        Frame index in the video.
    points : ndarray, shape (7, 2), float64, or None
        P1..P7, image (x, y) px; None when the frame is left out.
    quality : TrackQuality or None
    reason : str or None
        Why the frame is left out (None when it has points).
    """

    index: int
    points: np.ndarray | None
    quality: TrackQuality | None
    reason: str | None = None

    @property
    def ok(self) -> bool:
        return self.points is not None

    def as_json(self) -> dict[str, Any]:
        """tracked_points.json's entry: points and quality, or the reason."""
        if self.points is None:
            return {"reason": self.reason}
        return {"points": [[round(float(x), 3), round(float(y), 3)] for x, y in self.points],
                "quality": None if self.quality is None else self.quality.as_json()}


Refiner = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(image (H, W, 3) RGB, points (7, 2)) -> refined points (7, 2); raises InputError when refused."""


def _as_points(points: ReferencePoints | Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    if isinstance(points, ReferencePoints):
        d = points.as_dict()
        if len(d) != 7:
            raise InputError("tracking needs all seven points P1..P7 (P6 and P7 too)")
        return np.array([d[n] for n in POINT_NAMES], dtype=np.float64)
    arr = np.asarray(points, dtype=np.float64)
    if arr.shape != (7, 2) or not np.isfinite(arr).all():
        raise InputError(f"tracking needs seven finite (x, y) points P1..P7, got shape {arr.shape}")
    return arr


def to_reference(points: np.ndarray) -> ReferencePoints:
    """(7, 2) points as the spec's ReferencePoints."""
    return ReferencePoints.model_validate({n: (float(x), float(y)) for n, (x, y) in zip(POINT_NAMES, points,
                                                                                       strict=True)})


def _quads(points: np.ndarray, side_face: SideFace) -> tuple[np.ndarray, np.ndarray]:
    q = clicked_quads(to_reference(points), two_photo=False, side_face=side_face)
    return q.front, q.side



def _homography(src: np.ndarray, dst: np.ndarray, ransac_px: float) -> tuple[np.ndarray | None, np.ndarray]:
    """RANSAC homography src -> dst and its inlier mask (None, all False with fewer than 4)."""
    if len(src) < 4:
        return None, np.zeros(len(src), bool)
    H, mask = cv2.findHomography(src.astype(np.float64), dst.astype(np.float64), cv2.RANSAC, ransac_px,
                                 maxIters=500, confidence=0.995)
    if H is None or mask is None or not np.isfinite(H).all():
        return None, np.zeros(len(src), bool)
    return H, mask.ravel().astype(bool)


def _apply(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    out = cv2.perspectiveTransform(pts.reshape(-1, 1, 2).astype(np.float64), H)
    return np.asarray(out.reshape(-1, 2), dtype=np.float64)



class _Tracker:
    """Frame-to-frame tracking of one box's seven points (one direction in time)."""

    def __init__(self, grey: np.ndarray, points: np.ndarray, side_face: SideFace, index: int,
                 s: TrackerSettings, features: Sequence[np.ndarray] | None = None) -> None:
        self.s = s
        self.side_face = side_face
        self.state = self._seed(grey, points, index, steps=0, features=features)

    def _seed(self, grey: np.ndarray, points: np.ndarray, index: int, steps: int,
              features: Sequence[np.ndarray] | None = None, hist: np.ndarray | None = None) -> _State:
        if features is None:
            features = [_features(grey, q, self.s) for q in _quads(points, self.side_face)]
        return _State(grey, points.copy(), points.copy(), [_Face(f.copy(), f.copy()) for f in features],
                      [len(f) for f in features], _histogram(grey) if hist is None else hist, index, steps)

    def reanchor(self, points: np.ndarray) -> None:
        """The points of the current (last good) frame are now `points` (refined): features and
        anchor taken again there."""
        st = self.state
        self.state = self._seed(st.grey, points, st.index, st.steps, hist=st.hist)

    def step(self, grey: np.ndarray, index: int, *, wide: bool = False) -> _Step:
        """Track the last good frame's features to `grey` (frame `index`)."""
        st, s = self.state, self.s
        hist = _histogram(grey)
        if not wide and cv2.compareHist(st.hist, hist, cv2.HISTCMP_BHATTACHARYYA) > s.cut_distance:
            return _Step(None, reason="a cut to another scene (the picture changed at once)", cut=True,
                         hist=hist)
        win, levels = (s.wide_win_px, s.wide_levels) if wide else (s.win_px, s.levels)
        sizes = [len(f.now) for f in st.faces]
        allpts = np.concatenate([f.now for f in st.faces]) if sum(sizes) else np.zeros((0, 2), np.float32)
        new, ok, fb = _lk(st.grey, grey, allpts, win, levels)
        ok &= fb < s.fb_max_px
        if not ok.any():
            return _Step(None, reason="track lost: no feature on the box could be followed into this frame")
        fb_med = float(np.median(fb[ok]))
        faces, hs, inl = [], [], []
        start = 0
        for f, n in zip(st.faces, sizes, strict=True):
            sel = ok[start:start + n]
            cur, anc = new[start:start + n][sel], f.anchor[sel]
            start += n
            H, mask = _homography(anc, cur, s.ransac_px)
            hs.append(H)
            inl.append(int(mask.sum()))
            faces.append(_Face(cur[mask].astype(np.float32), anc[mask].astype(np.float32)))
        if hs[0] is None or inl[0] < s.min_inliers:
            return _Step(None, inliers=(inl[0], inl[1]), fb_px=fb_med,
                         reason=f"track lost: {inl[0]} features on the front follow the box "
                                f"(at least {s.min_inliers} needed; forward-backward error {fb_med:.2f} px)")
        pts = st.anchor_points
        moved = np.empty_like(pts)
        moved[list(_FRONT)] = _apply(hs[0], pts[list(_FRONT)])
        moved[3] = _apply(hs[0], pts[3:4])[0]
        side_h = None
        if hs[1] is not None and inl[1] >= s.min_side_inliers:
            side_h = hs[1]
            if s.side_model == "affine":
                # A narrow second face's homography extrapolates its far corners badly: an affine
                # motion of its inliers with the fold's two corners as the front moved them.
                shared = _fold_corners(self.side_face)
                src = np.concatenate([faces[1].anchor.astype(np.float64), pts[shared]])
                dst = np.concatenate([faces[1].now.astype(np.float64), moved[shared]])
                w = np.r_[np.ones(len(faces[1].now)), np.full(2, max(len(faces[1].now), 8.0))]
                A = np.column_stack([src, np.ones(len(src))]) * w[:, None]
                sol, *_ = np.linalg.lstsq(A, dst * w[:, None], rcond=None)
                side_h = np.vstack([sol.T, [0.0, 0.0, 1.0]])
        if side_h is not None and np.isfinite(side_h).all():
            moved[list(_SIDE_ONLY)] = _apply(side_h, pts[list(_SIDE_ONLY)])
        else:
            # Too little texture on the second face: its far corners move with the front (the
            # refinement on the edges sets them right on the frames reported).
            moved[list(_SIDE_ONLY)] = _apply(hs[0], pts[list(_SIDE_ONLY)])
        if not np.isfinite(moved).all():
            return _Step(None, reason="track lost: the front's motion is degenerate")
        return _Step(moved, inliers=(inl[0], inl[1]), fb_px=fb_med, faces=faces, hist=hist)

    def accept(self, grey: np.ndarray, index: int, step: _Step) -> None:
        """Frame `index` was tracked (`step`): it becomes the last good frame."""
        st, s = self.state, self.s
        assert step.points is not None
        faces = step.faces
        refresh = any(len(f.now) < s.refresh_fraction * max(c, 1)
                      for f, c in zip(faces, st.counts, strict=True))
        hist = _histogram(grey) if step.hist is None else step.hist
        self.state = _State(grey, step.points, st.anchor_points, faces, st.counts, hist, index, st.steps + 1)
        if refresh:
            # Fresh features, anchored on this frame's points.
            self.state = self._seed(grey, step.points, index, st.steps + 1, hist=hist)


def _confidence(inliers: int, fb_px: float, shift: float | None, s: TrackerSettings) -> float:
    """0..1 from the features that decide the points (`inliers`: the front's, or the whole box's)."""
    more = min(1.0, inliers / (4 * s.min_inliers))
    steady = float(np.exp(-fb_px / s.fb_max_px))
    snapped = 1.0 if shift is None else float(np.exp(-max(shift - 1.0, 0.0) / 4.0))
    return float(more * steady * snapped)


def _colour(image: np.ndarray) -> np.ndarray:
    """The image as the refinement takes it: (H, W, 3) (a grey frame repeated in three channels)."""
    return image if image.ndim == 3 else cv2.cvtColor(_grey(image), cv2.COLOR_GRAY2RGB)


def _track_one_way(frames: Iterable[tuple[int, np.ndarray]], start_grey: np.ndarray, start_points: np.ndarray,
                   start_index: int, side_face: SideFace, report: Collection[int],
                   refine: Refiner | None, s: TrackerSettings, k: float,
                   start_features: Sequence[np.ndarray]) -> dict[int, TrackedFrame]:
    """Track from the marked frame along `frames` (one direction; each (index, image) with image
    (H, W, 3) RGB or (H, W) grey), reporting the frames in `report`; the marked frame's grey
    image, features and points are already reduced by `k`."""
    tracker: _Tracker | BoxTracker
    if s.motion == "box":
        scaled = s if s.focal_px is None else replace(s, focal_px=s.focal_px * k)
        tracker = BoxTracker(start_grey, start_points * k, side_face, start_index, scaled)
    else:
        tracker = _Tracker(start_grey, start_points * k, side_face, start_index, s, start_features)
    out: dict[int, TrackedFrame] = {}
    lost_since: int | None = None
    ended: str | None = None
    for index, image in frames:
        wanted = index in report
        if ended is not None:
            if wanted:
                out[index] = TrackedFrame(index, None, None, ended)
            continue
        grey = _grey(image)
        if k != 1.0:
            grey = cv2.resize(grey, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)
        step = tracker.step(grey, index, wide=lost_since is not None)
        if step.points is None:
            if step.cut and lost_since is None:
                ended = f"the track ended at frame {index}: {step.reason}"
                if wanted:
                    out[index] = TrackedFrame(index, None, None, ended)
                continue
            lost_since = index if lost_since is None else lost_since
            if abs(index - tracker.state.index) > s.max_gap:
                ended = (f"the track was lost at frame {lost_since} and not found again within "
                         f"{s.max_gap} frames: {step.reason}")
            if wanted:
                out[index] = TrackedFrame(index, None, None, step.reason)
            continue
        lost_since = None
        last_good = tracker.state
        tracker.accept(grey, index, step)
        if not wanted:
            continue
        points = step.points / k
        shift: float | None = None
        if refine is not None:
            try:
                refined = refine(_colour(image), points)
            except InputError as exc:
                out[index] = TrackedFrame(index, None, _quality(step, None, tracker.state.steps, s),
                                          f"the box no longer fits the tracked points: {exc}")
                # A refused box anchors nothing: the track goes on from the last good frame, as
                # after a lost one.
                tracker.state = last_good
                lost_since = index
                continue
            shift = float(np.linalg.norm(refined - points, axis=1).max())
            if not isinstance(tracker, BoxTracker) or tracker.misfit(refined * k) / k <= s.refine_max_px:
                points = refined
                tracker.reanchor(points * k)
            # else: a refinement no pose of the tracked box reproduces (a corner snapped to another
            # edge) is not taken: the box's points are kept, the shift lowers their confidence.
        out[index] = TrackedFrame(index, points, _quality(step, shift, tracker.state.steps, s))
    return out


def _quality(step: _Step, shift: float | None, steps: int, s: TrackerSettings) -> TrackQuality:
    total = sum(step.inliers) if step.total is None else step.total
    follow = step.inliers[0] if step.total is None else step.total
    return TrackQuality(total, step.inliers[0], step.inliers[1], step.fb_px,
                        _confidence(follow, step.fb_px, shift, s), shift, steps)


def track_points(frames: Iterable[tuple[int, np.ndarray]],
                 points: ReferencePoints | Sequence[Sequence[float]] | np.ndarray, start: int, *,
                 report: Collection[int] | None = None, side_face: str = "auto",
                 refine: Refiner | None = None,
                 settings: TrackerSettings = DEFAULT_SETTINGS) -> dict[int, TrackedFrame]:
    """Carry seven points marked on frame `start` to the frames in `report`.

    Parameters
    ----------
    frames : iterable of (int, ndarray)
        The video's frames in increasing index order, each RGB uint8 of shape (H, W, 3) (or
        grey (H, W): a grey frame is refined in grey, repeated in three channels); it must hold
        `start` and should hold every frame between the reported ones (tracking takes small steps; a gap is
        bridged as a larger one). Frames before `start` are kept in grey (and in RGB when
        reported) until `start` is reached, then tracked backwards.
    points : ReferencePoints or array-like, shape (7, 2)
        P1..P7 on frame `start`, image (x, y) px, the engine's order.
    start : int
        The marked frame's index.
    report : collection of int, optional
        The frames to report (default: every frame). `start` is reported when listed, with its
        points as marked (refined when `refine` is given).
    side_face : {"auto", "right", "left", "top"}
        Which face P4, P5 and P7 mark (as `ScanSpec.side_face`).
    refine : callable, optional
        (image (H, W, 3), points (7, 2)) -> refined points (7, 2), raising InputError when it
        refuses them; `box_refiner` gives the engine's. None: the tracked points as they are.
    settings : TrackerSettings

    Returns
    -------
    dict of int to TrackedFrame
        One per reported frame that `frames` held: its points (7, 2) px and their quality, or
        why it is left out.

    Raises
    ------
    InputError
        The points are not seven finite points, describe no box face, or `start` is not in `frames`.
    """
    pts = _as_points(points)
    if settings.motion not in ("box", "faces"):
        raise InputError(f"the tracker's motion is 'box' or 'faces', not {settings.motion!r}")
    face = resolve_side_face(to_reference(pts), side_face)
    wanted: set[int] | None = None if report is None else set(report)
    before: list[tuple[int, np.ndarray]] = []
    it = iter(frames)
    first: tuple[int, np.ndarray] | None = None
    for index, image in it:
        if index == start:
            first = (index, image)
            break
        if index > start:
            break
        keep = image if wanted is None or index in wanted else _grey(image)
        before.append((index, keep))
    if first is None:
        raise InputError(f"the marked frame {start} is not among the video's frames")
    image0 = first[1]
    width = image0.shape[1]
    k = min(1.0, settings.max_width_px / width)
    grey0 = _grey(image0)
    if k != 1.0:
        grey0 = cv2.resize(grey0, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)
    everything: Collection[int] = wanted if wanted is not None else _Everything()
    out: dict[int, TrackedFrame] = {}
    start_points = pts
    shift: float | None = None
    if start in everything and refine is not None:
        try:
            refined = refine(_colour(image0), pts)
        except InputError as exc:
            raise InputError(f"the points marked on frame {start} do not fit a box: {exc}") from None
        shift = float(np.linalg.norm(refined - pts, axis=1).max())
        start_points = refined
    features0 = []
    for name, quad in zip(("front", "second"), _quads(start_points, face), strict=True):
        mask = _inset_mask(grey0.shape[:2], quad * k, settings.inset_px)
        if not mask.any():
            raise InputError(f"the {name} face the points mark on frame {start} is too small to track")
        features0.append(_features(grey0, quad * k, settings, mask))
    if start in everything:
        n0 = (len(features0[0]), len(features0[1]))
        confidence = _confidence(n0[0], 0.0, shift, settings)
        quality = TrackQuality(sum(n0), n0[0], n0[1], 0.0, confidence, shift, 0)
        out[start] = TrackedFrame(start, start_points, quality)
    out.update(_track_one_way(it, grey0, start_points, start, face, everything, refine, settings, k,
                              features0))
    if before:
        out.update(_track_one_way(reversed(before), grey0, start_points, start, face, everything, refine,
                                  settings, k, features0))
    return dict(sorted(out.items()))


class _Everything(Collection[int]):
    """Every frame index."""

    def __contains__(self, x: object) -> bool:
        return True

    def __iter__(self) -> Any:
        return iter(())

    def __len__(self) -> int:
        return 0

"""The box as one rigid body along a video: its camera pose per frame from every face's features.

The seven points of the marked frame fix a box model there (`fit_box_model`: the box's height and
depth in units of its width, the focal length unless it is known, and the camera's pose; the
principal point at the image centre, no lens distortion). Features are taken on every face the
camera sees (the lid too, which no point marks but whose corners are the box's) and placed on
the model's faces in 3-D by their rays; each later frame's pose is then re-fitted to the features
tracked into it (`pose_step`: Levenberg-Marquardt from the last pose, features farther than a few
px from the fitted box dropped), and the seven points are the model's corners projected with it.
A thin face whose homography extrapolates badly no longer decides its corners alone: every
feature on the box holds every corner.

`BoxTracker` is the tracker of `prismcore.video.tracking.track_points` with
`TrackerSettings.motion == "box"`. Pure functions over arrays: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from prismcore.errors import InputError
from prismcore.geometry.faces import SideFace
from prismcore.video.track_parts import (
    Face,
    State,
    Step,
    TrackerSettings,
    features,
    histogram,
    inset_mask,
    lk,
)

__all__ = ["BoxModel", "BoxTracker", "fit_box_model", "fit_pose", "pose_step"]

_DISTINCT = [0, 1, 2, 4, 5, 6]  # P1, P2, P3, P5, P6, P7 (P4 is P2 or P1)
# The box's six faces: (axis, at 0 or at the full length), in the model's frame (X along P1->P2,
# Y down the front, Z into the box).
_FACES = ((2, 0), (2, 1), (1, 0), (1, 1), (0, 0), (0, 1))


@dataclass(frozen=True)
class BoxModel:
    """A box seen by a pinhole camera.

    focal_px : float
    principal : ndarray, shape (2,)
        Image (x, y) px.
    height, depth : float
        In units of the box's width (P1->P2 is 1).
    side_face : {"right", "left", "top"}
        Which face P4, P5, P7 mark.
    """

    focal_px: float
    principal: np.ndarray
    height: float
    depth: float
    side_face: SideFace

    @property
    def camera(self) -> np.ndarray:
        """Camera matrix (3, 3)."""
        f, (cx, cy) = self.focal_px, self.principal
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    @property
    def sizes(self) -> np.ndarray:
        """(width, height, depth), shape (3,)."""
        return np.array([1.0, self.height, self.depth])

    def seven(self) -> np.ndarray:
        """P1..P7 in the model's frame, shape (7, 3)."""
        return _seven(self.side_face, self.height, self.depth)

    def project(self, pose: np.ndarray, pts: np.ndarray | None = None) -> np.ndarray:
        """Model points `pts` (N, 3) (default P1..P7) seen at `pose` (rvec, tvec: (6,)): (N, 2) px."""
        obj = self.seven() if pts is None else pts
        out, _ = cv2.projectPoints(obj.astype(np.float64), pose[:3], pose[3:], self.camera, None)
        return np.asarray(out.reshape(-1, 2), dtype=np.float64)

    def face_quads(self, pose: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
        """The faces the camera sees at `pose`: (axis, 0 or 1: the plane at 0 or at the box's
        size along it, image quad (4, 2))."""
        R, _ = cv2.Rodrigues(pose[:3])
        camera = -R.T @ pose[3:]
        size = self.sizes
        out = []
        for axis, far in _FACES:
            value = size[axis] * far
            normal = np.zeros(3)
            normal[axis] = 1.0 if far else -1.0
            centre = size / 2
            centre[axis] = value
            if normal @ (camera - centre) <= 0:
                continue
            u, v = (a for a in range(3) if a != axis)
            corners = np.zeros((4, 3))
            corners[:, axis] = value
            corners[:, u] = np.array([0, 1, 1, 0]) * size[u]
            corners[:, v] = np.array([0, 0, 1, 1]) * size[v]
            out.append((axis, far, self.project(pose, corners)))
        return out

    def back_project(self, pose: np.ndarray, px: np.ndarray, axis: int, value: float) -> np.ndarray:
        """Image points `px` (N, 2) on the model's plane `axis` = `value`, shape (N, 3)."""
        R, _ = cv2.Rodrigues(pose[:3])
        rays = np.c_[px, np.ones(len(px))] @ np.linalg.inv(self.camera).T @ R  # R^T d, row-wise
        camera = -R.T @ pose[3:]
        lam = (value - camera[axis]) / rays[:, axis]
        return np.asarray(camera + lam[:, None] * rays, dtype=np.float64)


def _seven(side_face: SideFace, h: float, d: float) -> np.ndarray:
    far = {"right": ((1, 0, d), (1, h, d)), "left": ((0, 0, d), (0, h, d)), "top": ((0, 0, d), (1, 0, d))}
    p4 = (1, 0, 0) if side_face == "right" else (0, 0, 0)
    return np.array([(0, 0, 0), (1, 0, 0), (1, h, 0), p4, far[side_face][0], (0, h, 0), far[side_face][1]],
                    dtype=np.float64)


def _depths(pose: np.ndarray, obj: np.ndarray) -> np.ndarray:
    R, _ = cv2.Rodrigues(pose[:3])
    return np.asarray((obj @ R.T)[:, 2] + pose[5])


def fit_box_model(points: np.ndarray, side_face: SideFace, image_shape: tuple[int, ...],
                  focal_px: float | None = None) -> tuple[BoxModel, np.ndarray]:
    """The box and the camera's pose that project onto the seven points.

    Parameters
    ----------
    points : ndarray, shape (7, 2)
        P1..P7, image px.
    side_face : {"right", "left", "top"}
    image_shape : tuple
        (H, W, ...): the principal point is the image centre.
    focal_px : float, optional
        Known focal length, px (else fitted, from several starts).

    Returns
    -------
    model : BoxModel
    pose : ndarray, shape (6,)
        rvec, tvec (model units: the box's width).

    Raises
    ------
    InputError
        No box in front of the camera projects onto the points.
    """
    H, W = image_shape[:2]
    c = np.array([(W - 1) / 2, (H - 1) / 2])
    target = np.asarray(points, dtype=np.float64)[_DISTINCT]
    diag = float(np.hypot(W, H))
    focals = [focal_px] if focal_px else [diag * m for m in (0.6, 0.9, 1.2, 1.6, 2.2)]
    free_f = focal_px is None

    def unpack(x: np.ndarray) -> tuple[BoxModel, np.ndarray]:
        f = float(x[8]) if free_f else float(focal_px or 0.0)
        return BoxModel(f, c, float(x[6]), float(x[7]), side_face), x[:6]

    def residual(x: np.ndarray) -> np.ndarray:
        model, pose = unpack(x)
        return (model.project(pose)[_DISTINCT] - target).ravel()

    best = None
    for f in focals:
        for h, d in ((0.3, 0.7), (0.5, 0.5), (1.0, 1.0)):
            start = BoxModel(f, c, h, d, side_face)
            ok, r, t = cv2.solvePnP(start.seven()[_DISTINCT], target, start.camera, None,
                                    flags=cv2.SOLVEPNP_SQPNP)
            if not ok:
                continue
            x0 = np.r_[r.ravel(), t.ravel(), h, d, [f] if free_f else []]
            sol = least_squares(residual, x0, x_scale="jac")
            model, pose = unpack(sol.x)
            behind = (_depths(pose, model.seven()) <= 0).any()
            if behind or min(model.height, model.depth, model.focal_px) <= 0:
                continue  # the mirror image behind the camera, or a box inside out
            if best is None or sol.cost < best.cost:
                best = sol
    if best is None:
        raise InputError("no box in front of the camera projects onto the seven points")
    model, pose = unpack(best.x)
    return model, np.array(pose, dtype=np.float64)


def fit_pose(model: BoxModel, points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The pose (6,) whose projection of the model is closest to `points` (7, 2), from `pose`."""
    obj = model.seven()[_DISTINCT]
    r, t = cv2.solvePnPRefineLM(obj, np.asarray(points, np.float64)[_DISTINCT], model.camera, None,
                                pose[:3].reshape(3, 1).copy(), pose[3:].reshape(3, 1).copy())
    return np.asarray(np.r_[r.ravel(), t.ravel()], dtype=np.float64)


def pose_step(model: BoxModel, X: np.ndarray, px: np.ndarray, pose: np.ndarray, max_px: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """The pose re-fitted to features: model points `X` (N, 3) seen at `px` (N, 2), from `pose` (6,).

    Levenberg-Marquardt from `pose`, then again without the features farther than 2 * `max_px`,
    then `max_px`, from the box it fits. Returns the pose (6,) and the inlier mask (N,).
    """
    obj, img = X.astype(np.float64), px.astype(np.float64)
    r, t = pose[:3].reshape(3, 1).copy(), pose[3:].reshape(3, 1).copy()
    keep = np.ones(len(obj), bool)
    for limit in (None, 2 * max_px, max_px):
        if limit is not None:
            err = np.linalg.norm(model.project(np.r_[r.ravel(), t.ravel()], obj) - img, axis=1)
            keep = err < limit
        if keep.sum() < 4:
            return np.r_[r.ravel(), t.ravel()], keep
        r, t = cv2.solvePnPRefineLM(obj[keep], img[keep], model.camera, None, r, t)
    return np.r_[r.ravel(), t.ravel()], keep


class BoxTracker:
    """Frame-to-frame tracking of the box's pose (one direction in time), as `tracking._Tracker`."""

    def __init__(self, grey: np.ndarray, points: np.ndarray, side_face: SideFace, index: int,
                 s: TrackerSettings) -> None:
        self.s = s
        self.side_face = side_face
        self.model, pose = fit_box_model(points, side_face, grey.shape, s.focal_px)
        self.state = self._seed(grey, points, index, 0, pose)

    def _features(self, grey: np.ndarray, pose: np.ndarray, away: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Features on the faces seen at `pose` (not within min_distance of `away`): (px (N, 2)
        float32, model points (N, 3), face id (N,): 0 the front, 1 the second face, 2 another)."""
        second = {"right": (0, 1), "left": (0, 0), "top": (1, 0)}[self.side_face]
        pxs, xs, ids = [np.zeros((0, 2), np.float32)], [np.zeros((0, 3))], [np.zeros(0, int)]
        for axis, far, quad in self.model.face_quads(pose):
            mask = inset_mask(grey.shape[:2], quad, self.s.inset_px)
            if away is not None and len(away):
                for x, y in np.round(away).astype(int):
                    cv2.circle(mask, (int(x), int(y)), int(self.s.min_distance_px), 0, -1)
            found = features(grey, quad, self.s, mask)
            if not len(found):
                continue
            pxs.append(found)
            value = float(self.model.sizes[axis] * far)
            xs.append(self.model.back_project(pose, found.astype(np.float64), axis, value))
            ids.append(np.full(len(found), 0 if (axis, far) == (2, 0) else 1 if (axis, far) == second else 2))
        return np.concatenate(pxs).astype(np.float32), np.concatenate(xs), np.concatenate(ids)

    def _seed(self, grey: np.ndarray, points: np.ndarray, index: int, steps: int, pose: np.ndarray,
              hist: np.ndarray | None = None) -> State:
        px, X, ids = self._features(grey, pose)
        return State(grey, points.copy(), points.copy(), [Face(px, px.copy())], [len(px)],
                     histogram(grey) if hist is None else hist, index, steps, pose=pose, model_points=X,
                     face_ids=ids)

    def misfit(self, points: np.ndarray) -> float:
        """RMS px between `points` (7, 2) and the box model at the pose fitted to them (from the
        current one): how far they are from any view of the tracked box."""
        st = self.state
        assert st.pose is not None
        pose = fit_pose(self.model, points, st.pose)
        d = self.model.project(pose)[_DISTINCT] - np.asarray(points, np.float64)[_DISTINCT]
        return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))

    def reanchor(self, points: np.ndarray) -> None:
        """The current (last good) frame's points are `points` (refined): the pose is fitted to
        them and the features are taken again."""
        st = self.state
        assert st.pose is not None
        pose = fit_pose(self.model, points, st.pose)
        self.state = self._seed(st.grey, self.model.project(pose), st.index, st.steps, pose, st.hist)

    def step(self, grey: np.ndarray, index: int, *, wide: bool = False) -> Step:
        """Track the last good frame's features to `grey` (frame `index`) and fit the pose to them."""
        st, s = self.state, self.s
        assert st.pose is not None and st.model_points is not None and st.face_ids is not None
        hist = histogram(grey)
        if not wide and cv2.compareHist(st.hist, hist, cv2.HISTCMP_BHATTACHARYYA) > s.cut_distance:
            return Step(None, reason="a cut to another scene (the picture changed at once)", cut=True,
                        hist=hist)
        win, levels = (s.wide_win_px, s.wide_levels) if wide else (s.win_px, s.levels)
        new, ok, fb = lk(st.grey, grey, st.faces[0].now, win, levels)
        ok &= fb < s.fb_max_px
        if ok.sum() < s.min_inliers:
            return Step(None, reason=f"track lost: {int(ok.sum())} features on the box could be followed "
                                     f"into this frame (at least {s.min_inliers} needed)")
        fb_med = float(np.median(fb[ok]))
        X, ids = st.model_points[ok], st.face_ids[ok]
        pose, inl = pose_step(self.model, X, new[ok], st.pose, s.ransac_px)
        counts = (int((inl & (ids == 0)).sum()), int((inl & (ids == 1)).sum()))
        if inl.sum() < s.min_inliers or not np.isfinite(pose).all():
            return Step(None, inliers=counts, fb_px=fb_med,
                        reason=f"track lost: {int(inl.sum())} features follow the box "
                               f"(at least {s.min_inliers} needed; forward-backward error {fb_med:.2f} px)")
        if (_depths(pose, self.model.seven()) <= 0).any():
            return Step(None, reason="track lost: the box's pose went behind the camera")
        kept = new[ok][inl].astype(np.float32)
        return Step(self.model.project(pose), inliers=counts, fb_px=fb_med, faces=[Face(kept, kept.copy())],
                    hist=hist, pose=pose, model_points=X[inl], face_ids=ids[inl], total=int(inl.sum()))

    def accept(self, grey: np.ndarray, index: int, step: Step) -> None:
        """Frame `index` was tracked (`step`): it becomes the last good frame; features are added
        (away from the survivors) once fewer than `refresh_fraction` of them are left."""
        st, s = self.state, self.s
        assert step.points is not None and step.pose is not None
        assert step.model_points is not None and step.face_ids is not None
        px, X, ids = step.faces[0].now, step.model_points, step.face_ids
        count = st.counts[0]
        if len(px) < s.refresh_fraction * max(count, 1):
            more_px, more_X, more_ids = self._features(grey, step.pose, away=px)
            px = np.concatenate([px, more_px]).astype(np.float32)
            X, ids = np.concatenate([X, more_X]), np.concatenate([ids, more_ids])
            count = len(px)
        self.state = State(grey, step.points, step.points, [Face(px, px.copy())], [count],
                           histogram(grey) if step.hist is None else step.hist, index, st.steps + 1,
                           pose=step.pose, model_points=X, face_ids=ids)

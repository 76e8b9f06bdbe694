"""The tracker's parts: its settings, the frames' grey levels and histograms, features inside a
face, Lucas-Kanade checked forward and backward, and the state a tracker keeps between frames.

Shared by the trackers of `prismcore.video.tracking` (each face's homography) and
`prismcore.video.box_motion` (the box as one rigid body). Pure functions over arrays: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from prismcore.geometry.faces import quad_area

__all__ = ["DEFAULT_SETTINGS", "Face", "State", "Step", "TrackerSettings", "features", "grey", "histogram",
           "inset_mask", "lk"]

@dataclass(frozen=True)
class TrackerSettings:
    """The tracker's knobs (defaults measured on the real cookie-box video and on renders)."""

    max_features: int = 160
    """Most features kept per face."""
    min_distance_px: float = 5.0
    """Least distance between two features (goodFeaturesToTrack's minDistance), px."""
    quality: float = 0.005
    """goodFeaturesToTrack's qualityLevel."""
    inset_px: float = 3.0
    """Features are taken this far inside a face's sides, px."""
    win_px: int = 21
    """Lucas-Kanade window side, px (odd)."""
    levels: int = 3
    """Pyramid levels beyond the image itself."""
    fb_max_px: float = 1.0
    """A feature tracked forward then back must land this close to where it started, px."""
    ransac_px: float = 1.5
    """RANSAC reprojection threshold of each face's homography, px."""
    min_inliers: int = 10
    """The front's homography needs this many inliers, else the frame is lost."""
    min_side_inliers: int = 8
    """Fewer on the second face: its far corners move with the front's homography instead."""
    refresh_fraction: float = 0.6
    """Features are taken again on a face once fewer than this fraction of them survive."""
    cut_distance: float = 0.5
    """A grey-level histogram Bhattacharyya distance from one frame to the next past this is a cut."""
    max_gap: int = 30
    """Frames after the last good one over which a lost track is searched for again."""
    wide_win_px: int = 41
    """The re-seeding search's window side, px."""
    wide_levels: int = 5
    """The re-seeding search's pyramid levels."""
    side_model: str = "homography"
    """How the second face's far corners move: "homography" (its own RANSAC homography) or
    "affine" (an affine motion of its inliers held to the fold as the front moved it)."""
    max_width_px: int = 1280
    """Frames wider than this are tracked at a reduced size (the points are scaled back)."""
    motion: str = "box"
    """How the points move: "box" (the box as one rigid body: the camera's pose from every face's
    features, `prismcore.video.box_motion`) or "faces" (each marked face's own homography)."""
    focal_px: float | None = None
    """The box tracker's focal length, px, when known (else fitted to the marked frame's points)."""
    refine_max_px: float = 1.0
    """The box tracker takes a refinement only when a pose of its box model projects within this
    of the refined points (RMS px; else the tracked points are kept, with the refinement's shift
    in their quality and a lower confidence)."""


DEFAULT_SETTINGS = TrackerSettings()

def grey(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image if image.dtype == np.uint8 else np.clip(image, 0, 255).astype(np.uint8)
    if image.dtype != np.uint8:
        image = np.clip(image, 0, 255).astype(np.uint8)
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def histogram(grey: np.ndarray) -> np.ndarray:
    small = grey[::4, ::4]
    return cv2.calcHist([small], [0], None, [32], [0, 256])


def inset_mask(shape: tuple[int, int], quad: np.ndarray, inset_px: float) -> np.ndarray:
    """uint8 mask of `quad` shrunk by `inset_px` toward its centre (along each side's normal)."""
    centre = quad.mean(axis=0)
    lines = []
    for i in range(4):
        p, q = quad[i], quad[(i + 1) % 4]
        n = np.array([q[1] - p[1], p[0] - q[0]])
        norm = float(np.linalg.norm(n))
        if norm < 1e-9:
            return np.zeros(shape, np.uint8)
        n /= norm
        c = -float(n @ p)
        if n @ centre + c < 0:
            n, c = -n, -c
        lines.append((n, c - inset_px))
    corners = []
    for i in range(4):
        (n1, c1), (n2, c2) = lines[(i - 1) % 4], lines[i]
        a = np.stack([n1, n2])
        if abs(np.linalg.det(a)) < 1e-9:
            return np.zeros(shape, np.uint8)
        corners.append(np.linalg.solve(a, -np.array([c1, c2])))
    mask = np.zeros(shape, np.uint8)
    poly = np.array(corners)
    # An inset that turned the quad inside out (a face thinner than twice the inset) is empty.
    if np.sign(quad_area(poly)) != np.sign(quad_area(quad)):
        return mask
    cv2.fillConvexPoly(mask, np.round(poly * 16).astype(np.int32), 255, lineType=cv2.LINE_8, shift=4)
    return mask


def features(grey: np.ndarray, quad: np.ndarray, s: TrackerSettings, mask: np.ndarray | None = None
              ) -> np.ndarray:
    """Features inside `quad` (inset; `mask`: that inset quad's mask, already drawn), shape (N, 2) float32."""
    if mask is None:
        mask = inset_mask(grey.shape[:2], quad, s.inset_px)
    if not mask.any():
        return np.zeros((0, 2), np.float32)
    found = cv2.goodFeaturesToTrack(grey, s.max_features, s.quality, s.min_distance_px, mask=mask,
                                    blockSize=5)
    return np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2).astype(np.float32)


def lk(prev: np.ndarray, cur: np.ndarray, pts: np.ndarray, win: int, levels: int
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Features `pts` of `prev` tracked to `cur`, checked back: (new positions (N, 2), kept mask,
    forward-backward error (N,) px)."""
    if len(pts) == 0:
        return pts, np.zeros(0, bool), np.zeros(0)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03)
    p0 = pts.reshape(-1, 1, 2)
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, winSize=(win, win), maxLevel=levels,
                                          criteria=crit)
    p0r, st2, _ = cv2.calcOpticalFlowPyrLK(cur, prev, p1, None, winSize=(win, win), maxLevel=levels,
                                           criteria=crit)
    fb = np.linalg.norm((p0r - p0).reshape(-1, 2), axis=1)
    ok = (st1.ravel() == 1) & (st2.ravel() == 1) & np.isfinite(fb)
    return p1.reshape(-1, 2), ok, fb



@dataclass
class Face:
    """One face's features: where they are now and where they were on the anchor frame."""

    now: np.ndarray  # (N, 2) float32, current frame
    anchor: np.ndarray  # (N, 2) float32, the anchor frame


@dataclass
class State:
    """The tracker's state after a good frame."""

    grey: np.ndarray
    points: np.ndarray  # (7, 2) in this frame
    anchor_points: np.ndarray  # (7, 2) on the anchor frame
    faces: list[Face]  # front, side
    counts: list[int]  # features per face when last taken
    hist: np.ndarray
    index: int
    steps: int = 0
    pose: np.ndarray | None = None  # the box's tracker: the camera's pose (rvec, tvec), (6,)
    model_points: np.ndarray | None = None  # ... the features' points on the box model, (N, 3)
    face_ids: np.ndarray | None = None  # ... each feature's face: 0 front, 1 the second face, 2 another


@dataclass
class Step:
    points: np.ndarray | None
    inliers: tuple[int, int] = (0, 0)
    fb_px: float = 0.0
    reason: str | None = None
    cut: bool = False
    faces: list[Face] = field(default_factory=list)
    hist: np.ndarray | None = None  # the frame's grey-level histogram (the cut check's)
    pose: np.ndarray | None = None  # the box's tracker: as State's
    model_points: np.ndarray | None = None
    face_ids: np.ndarray | None = None
    total: int | None = None  # features that follow the box, all faces (None: inliers' sum)


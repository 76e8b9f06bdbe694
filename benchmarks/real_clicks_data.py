"""Real photos with exact ground truth: YCB-Video's video 0000, frames 1-10 (MIT licence).

The frames are read in place from ``../shared/data/ycb-video-0000/`` (beside the repository; its
README and LICENSE say what they are), never copied into the repository. Two box-shaped objects
stand on a desk: 009_gelatin_box (class 8) and 061_foam_brick (class 21).

The truth, as the data's README describes it: each box's frame in model coordinates from planes
fitted to its visible faces (the model coordinates of its labelled pixels, `vertmap`, pooled over
the ten frames, which share the model frame), its extent along each axis from those planes (a
face seen) or from the farthest surface point seen (a face never seen), its eight corners moved
by the frame's pose and projected with K: the true corner pixels and the true sizes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ycb-video-0000"
FRAMES = tuple(range(1, 11))
OBJECTS = {8: "gelatin box", 21: "foam brick"}
_PLANE_TOL_M = 0.0008  # a point within this of a face's plane belongs to it (the faces bulge ~1 mm)
_TRIM = 0.0  # percent of the extreme points left out of a far extent (rendered: every one is on the model)


def available() -> bool:
    """Whether the frames are beside the repository (a test skips, naming the folder, if not)."""
    return all(
        (DATA / f"{i:06d}-{kind}").is_file()
        for i in FRAMES
        for kind in ("color.png", "label.png", "meta.mat")
    )


@dataclass(frozen=True)
class Truth:
    """One box in one frame: the clicks a perfect user makes and the sizes they measure.

    points : the seven points P1-P7 (image x, y px) at the projected sharp corners
    side_face : "right", "left" or "top": which second face P4, P5 and P7 mark
    sizes_mm : width (P1-P2), height (P2-P3), depth (along the second face)
    """

    frame: int
    name: str
    points: tuple[tuple[float, float], ...]
    side_face: str
    sizes_mm: tuple[float, float, float]


def _meta(frame: int) -> dict[str, np.ndarray]:
    import scipy.io

    meta: dict[str, np.ndarray] = scipy.io.loadmat(str(DATA / f"{frame:06d}-meta.mat"))
    return meta


def image(frame: int) -> np.ndarray:
    """The frame's photo, RGB uint8 (480, 640, 3)."""
    bgr = cv2.imread(str(DATA / f"{frame:06d}-color.png"), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FileNotFoundError(DATA / f"{frame:06d}-color.png")
    return np.ascontiguousarray(bgr[..., ::-1])


def intrinsics(frame: int = 1) -> np.ndarray:
    """K (3, 3): fx 1066.778, fy 1067.487, cx 312.987, cy 241.311."""
    return np.asarray(_meta(frame)["intrinsic_matrix"], dtype=np.float64)


def _plane(points: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float, np.ndarray]:
    """The plane most points lie on (RANSAC, then least squares): unit normal, offset, inliers."""
    best = np.zeros(len(points), dtype=bool)
    for _ in range(400):
        a, b, c = points[rng.choice(len(points), 3, replace=False)]
        normal = np.cross(b - a, c - a)
        if np.linalg.norm(normal) < 1e-12:
            continue
        normal /= np.linalg.norm(normal)
        inliers = np.abs((points - a) @ normal) < _PLANE_TOL_M
        if inliers.sum() > best.sum():
            best = inliers
    centre = points[best].mean(axis=0)
    normal = np.linalg.svd(points[best] - centre, full_matrices=False)[2][-1]
    return normal, float(normal @ centre), best


@cache
def box_in_model(cls: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box's frame in model coordinates: axes (3, 3) rows, and per axis its low and high
    extent (m), pooled over the ten frames."""
    pooled = []
    for frame in FRAMES:
        label = cv2.imread(str(DATA / f"{frame:06d}-label.png"), cv2.IMREAD_UNCHANGED)
        vertmap = _meta(frame)["vertmap"]
        pts = vertmap[label == cls].astype(np.float64)
        pooled.append(pts[np.abs(pts).sum(axis=1) > 0])
    points = np.concatenate(pooled)
    rng = np.random.default_rng(0)
    rest, normals, offsets = points, [], []
    for _ in range(3):  # the faces seen: at most three of a box
        if len(rest) < 500:
            break
        normal, offset, _ = _plane(rest, rng)
        # Each plane's normal pointing out of the box (the points lie on its inner side).
        if np.median(points @ normal) > offset:
            normal, offset = -normal, -offset
        normals.append(normal)
        offsets.append(offset)
        rest = rest[np.abs(rest @ normal - offset) >= 2 * _PLANE_TOL_M]
    stack = np.array(normals)
    if len(normals) == 2:
        stack = np.vstack([stack, np.cross(stack[0], stack[1])])
    u, _, vt = np.linalg.svd(stack)
    axes = u @ vt  # the nearest orthonormal frame to the faces' normals, in the same order
    low, high = np.empty(3), np.empty(3)
    for k, axis in enumerate(axes):
        along = points @ axis
        low[k], high[k] = np.percentile(along, _TRIM), np.percentile(along, 100 - _TRIM)
        if k < len(offsets):
            high[k] = float(np.median(along[np.abs(along - offsets[k] * (normals[k] @ axis)) < _PLANE_TOL_M]))
    return axes, low, high


def _corners(cls: int) -> np.ndarray:
    """The eight corners (8, 3) in model coordinates, index bits (axis 0, 1, 2) high."""
    axes, low, high = box_in_model(cls)
    out = []
    for i in range(8):
        coords = [high[k] if i >> k & 1 else low[k] for k in range(3)]
        out.append(sum(c * a for c, a in zip(coords, axes, strict=True)))
    return np.array(out)


def truth(frame: int, cls: int) -> Truth:
    """The seven points and sizes of box `cls` in `frame`: its front the most frontal upright
    face, its second face the next largest one seen (side or top)."""
    meta = _meta(frame)
    index = list(meta["cls_indexes"].ravel()).index(cls)
    pose = meta["poses"][:, :, index]
    R, t = pose[:, :3], pose[:, 3]
    K = np.asarray(meta["intrinsic_matrix"], dtype=np.float64)
    axes, low, high = box_in_model(cls)
    corners = _corners(cls)
    cam = corners @ R.T + t
    pix = cam @ K.T
    pix = pix[:, :2] / pix[:, 2:]
    # Up: the axis whose direction in the camera points most up the image (-y).
    dirs = axes @ R.T
    up = int(np.argmax(np.abs(dirs[:, 1])))
    up_sign = 1 if dirs[up, 1] < 0 else 0
    faces = []
    for k in range(3):
        for sign in (0, 1):
            ids = [i for i in range(8) if (i >> k & 1) == sign]
            centre = cam[ids].mean(axis=0)
            outward = dirs[k] * (1 if sign else -1)
            if outward @ centre >= 0:
                continue  # faces away from the camera
            area = abs(cv2.contourArea(cv2.convexHull(pix[ids].astype(np.float32))))
            faces.append((area, k, sign, ids))
    upright = [f for f in faces if f[1] != up]
    front = max(upright, key=lambda f: f[0])
    second = max((f for f in faces if f is not front), key=lambda f: f[0])
    _, fk, _, fids = front
    top_ids = [i for i in fids if (i >> up & 1) == up_sign]
    bottom_ids = [i for i in fids if i not in top_ids]
    tl, tr = sorted(top_ids, key=lambda i: pix[i, 0])
    bl, br = sorted(bottom_ids, key=lambda i: pix[i, 0])
    sk = second[1]
    if sk == up:
        side_face = "top"
        depth_of = {tl: tl ^ (1 << fk), tr: tr ^ (1 << fk)}
        p4, p5, p7 = tl, depth_of[tl], depth_of[tr]
    else:
        side_face = "right" if (second[3] and tr in second[3]) else "left"
        if side_face == "right":
            p4, p5, p7 = tr, tr ^ (1 << fk), br ^ (1 << fk)
        else:
            p4, p5, p7 = tl, tl ^ (1 << fk), bl ^ (1 << fk)
    order = (tl, tr, br, p4, p5, bl, p7)
    size = high - low
    width = float(np.linalg.norm(corners[tr] - corners[tl]))
    height = float(np.linalg.norm(corners[br] - corners[tr]))
    depth = float(size[fk])
    return Truth(
        frame,
        OBJECTS[cls],
        tuple((float(x), float(y)) for x, y in pix[list(order)]),
        side_face,
        (1000 * width, 1000 * height, 1000 * depth),
    )


def all_truths() -> list[Truth]:
    """Every box in every frame (20)."""
    return [truth(frame, cls) for frame in FRAMES for cls in OBJECTS]

"""Several photo-like photos of ONE box, as a user takes them walking around it with one phone.

`photo_like_views` draws one box, one camera (focal length, lens distortion), one edge rounding
and one look (style, colours, label) from a seed, then several poses, each showing the front, the
right side and the top at a distinct angle, and renders each as `photo_like.photo_like_scene` renders
its one photo (distortion, rounded edges, vignetting, noise, blur, JPEG), with its own clicks
0-3 px off. The known edge is the same for every view. Ground truth for the engine's joint fit
(`prismcore.multiview.joint`).
"""

from __future__ import annotations

import math

import numpy as np

from prismcore.errors import InputError

from .models import Box, Realism
from .photo_like import _POINT_ORDER, PhotoLikeScene, photo_like_clicks, photo_like_pose, photo_like_setup
from .render import _scene

__all__ = ["MIN_VIEW_SEPARATION_DEG", "photo_like_views"]

MIN_VIEW_SEPARATION_DEG = 12.0
"""Every two views' directions to the box (from its front face's centre) differ by this much (by
half or a quarter of it for the rare box whose poses leave too little room)."""


def _pose(rng: np.random.Generator, box: Box, K: np.ndarray, realism: Realism, w: int, h: int,
          taken: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """R, t and the face angles of a photo-like pose at least MIN_VIEW_SEPARATION_DEG from `taken`
    (unit directions from the front's centre to earlier cameras, less for a box that leaves too
    little room), which it extends."""
    centre = np.array([box.width_mm / 2, box.height_mm / 2, 0.0])
    for attempt in range(6000):
        # Past 2000 tries the box and the views drawn so far leave little room: ask for less.
        separation = MIN_VIEW_SEPARATION_DEG / (1 << (attempt // 2000))

        def apart(camera: np.ndarray, separation: float = separation) -> bool:
            direction = (camera - centre) / np.linalg.norm(camera - centre)
            return all(math.degrees(math.acos(min(1.0, float(direction @ o)))) >= separation
                       for o in taken)

        if (pose := photo_like_pose(rng, box, K, realism, (w, h), apart)) is not None:
            R, t, angles = pose
            camera = -R.T @ t  # the turn about the camera's centre leaves it where it was
            taken.append((camera - centre) / np.linalg.norm(camera - centre))
            return R, t, angles
    raise RuntimeError("no photo-like pose found that differs enough from the others")  # pragma: no cover


def photo_like_views(seed: int, views: int = 3, *, image_size: tuple[int, int] = (1280, 960),
                     edge_radius_mm: float | None = None) -> list[PhotoLikeScene]:
    """Photo-like photos of one random box from `views` viewpoints, one phone, one user.

    Drawn from `seed` alone, with `photo_like_scene`'s ranges: box sides 40-300 x 30-220 x
    25-180 mm; a focal length of 0.7-1.2 times the image width; distortion k1 in [-0.15, 0.10],
    k2 in [-0.03, 0.03]; rounded edges 0.5-2.5 mm; per view a pose that shows the front, right and
    top faces with the front's and the side's normals 20-60 degrees from the view, rolled up to 8
    degrees and off-centre, its direction from the box at least MIN_VIEW_SEPARATION_DEG from every
    other view's; one style and one surface (the box looks the same in every photo; each photo's
    JPEG is the same quality, EXIF for even seeds); each view's clicks 0-3 px off; one known edge
    for all.

    Parameters
    ----------
    seed : int
        Everything follows from it (same seed, same bytes). Not the same scenes as
        `photo_like_scene(seed)`.
    views : int
        Number of photos, at least 1.
    image_size : (int, int)
        (width, height) px.
    edge_radius_mm : float or None
        Overrides the drawn edge radius.

    Returns
    -------
    list of PhotoLikeScene
        One per view, in drawing order; same box, camera matrix, distortion and known edge.
    """
    w, h = int(image_size[0]), int(image_size[1])
    if min(w, h) < 64:
        raise InputError(f"image_size must be at least 64x64 px, got {image_size!r}")
    if views < 1:
        raise InputError(f"views must be at least 1, got {views!r}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 20]))
    box, focal, realism, style, K = photo_like_setup(rng, seed, (w, h), edge_radius_mm)
    surface = int(rng.integers(1 << 31))  # the render's seed: the same colours and label in every view
    known = str(rng.choice(["width", "height", "depth"]))
    taken: list[np.ndarray] = []
    out = []
    for _ in range(views):
        R, t, angles = _pose(rng, box, K, realism, w, h, taken)
        front_centre = R @ np.array([box.width_mm / 2, box.height_mm / 2, 0.0]) + t
        scene = _scene(box, "oblique", (w, h), focal, float(front_centre[2]), R, t, style, surface,
                       _POINT_ORDER, "front", None, realism=realism)
        clicks = photo_like_clicks(rng, scene)
        out.append(PhotoLikeScene(scene, clicks, known, realism.exif is not None, style, realism, angles))
    return out

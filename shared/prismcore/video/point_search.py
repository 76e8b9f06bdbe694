"""The zero-click search along a video: each selected frame's points found in the frame, the
search for the next frame starting at the box the last one found.

A hand-held video shows one box moving a little from frame to frame; other objects may come
and go. Searching every frame afresh could pick another box (or refuse two candidates), so the
centre of the last points found is the next frame's hint (`locate.find_points`: the box around
it is chosen). The spec's own hint, if any, starts the first frame; its region applies to every
frame. A frame where nothing is found around the last box is searched again from the spec's
own hint (or none): a box that moved far between two selected frames is found again, not lost
for the rest of the video.
"""

from __future__ import annotations

import numpy as np

from prismcore.errors import InputError
from prismcore.locate.search import Found, resolve_points
from prismcore.spec import ReferencePoints, ScanSpec
from prismcore.video.frames import frame_spec

__all__ = ["FrameSearch", "points_centre"]


def points_centre(points: ReferencePoints) -> tuple[float, float]:
    """Mean (x, y) px of the points given: inside the box's outline (its corners' convex hull)."""
    given = [xy for xy in points.as_dict().values() if xy is not None]
    return (sum(x for x, _ in given) / len(given), sum(y for _, y in given) / len(given))


class FrameSearch:
    """Finds the points of a video spec with points "auto", frame after frame, in frame order.

    Parameters
    ----------
    spec : ScanSpec
        A video spec (`frames` set) whose points are "auto" (`auto_points` set).
    hint : (float, float) or None, optional
        Where the first search starts (image px): `hint` of a search that went before (a split
        taken up where it was left); by default the spec's own hint.
    """

    def __init__(self, spec: ScanSpec, *, hint: tuple[float, float] | None = None) -> None:
        if spec.frames is None or spec.auto_points is None:
            raise ValueError("FrameSearch needs a video spec with points \"auto\"")
        self._spec = spec
        self._hint = spec.auto_points.hint if hint is None else hint

    @property
    def hint(self) -> tuple[float, float] | None:
        """Where the next frame's search starts: the centre of the last points found."""
        return self._hint

    def resolve(self, index: int, image: np.ndarray) -> tuple[ScanSpec, Found]:
        """Frame `index`'s photo spec with the points found in `image` (H, W, 3) RGB, and what
        the search found; the next call starts from this frame's box.

        Raises
        ------
        InputError
            With the search's reason when it refuses this frame (the hint is kept).
        """
        photo = frame_spec(self._spec, index)
        assert photo.auto_points is not None  # frame_spec keeps the spec's auto_points
        first = photo.auto_points.hint
        try:
            resolved, found = resolve_points(self._from(photo, self._hint), image)
        except InputError:
            if self._hint == first:
                raise
            resolved, found = resolve_points(self._from(photo, first), image)
        if found.points is None:  # resolve_points raises first: kept for the type checker
            raise InputError(f"points auto: frame {index}: no points found")
        self._hint = points_centre(found.points)
        return resolved, found

    @staticmethod
    def _from(photo: ScanSpec, hint: tuple[float, float] | None) -> ScanSpec:
        assert photo.auto_points is not None
        return photo.model_copy(update={"auto_points": photo.auto_points.model_copy(update={"hint": hint})})

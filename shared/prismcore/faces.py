"""Face quadrilaterals built from the reference points, and their validation.

A quad is a float64 array of shape (4, 2) holding image positions (x, y) in the order
top-left, top-right, bottom-right, bottom-left. Edge i runs from corner i to corner i+1:
0 top, 1 right, 2 bottom, 3 left.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .spec import ReferencePoints

__all__ = ["FaceQuads", "clicked_quads", "paper_rectangles", "quad_area", "quad_labels",
           "validate_points", "validate_quad"]

MIN_FACE_PX = 4.0


@dataclass(frozen=True)
class FaceQuads:
    """The front and side quads as clicked (before edge refinement)."""

    front: np.ndarray
    side: np.ndarray
    front_complete: bool  # p6 was given, so the front quad is not a parallelogram guess
    side_complete: bool  # p7 was given


def quad_area(quad: np.ndarray) -> float:
    """Signed shoelace area; positive for a clockwise quad in image coordinates (y down)."""
    x, y = quad[:, 0], quad[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def clicked_quads(
    points: ReferencePoints, *, two_photo: bool, side_height_px: float | None = None
) -> FaceQuads:
    """Build both face quads from the clicks.

    In single-photo mode the side face shares the front's right edge: its lower-left corner is
    p3 moved by (p4 - p2). In two-photo mode without p7 the side face is taken as tall as
    `side_height_px` (the front's height in side-photo pixels), or as the front's height in
    pixels when that is unknown.
    """
    p = {k: np.asarray(v, dtype=np.float64) for k, v in points.as_dict().items()}
    front_bl = p["p6"] if "p6" in p else p["p1"] + p["p3"] - p["p2"]
    front = np.stack([p["p1"], p["p2"], p["p3"], front_bl])
    if two_photo:
        if "p7" in p:
            down = p["p7"] - p["p5"]
        else:
            height = side_height_px or float(np.linalg.norm(p["p3"] - p["p2"]))
            down = np.array([0.0, height])
        side_bl = p["p4"] + down
    else:
        side_bl = p["p3"] + (p["p4"] - p["p2"])
    side_br = p["p7"] if "p7" in p else p["p5"] + (side_bl - p["p4"])
    side = np.stack([p["p4"], p["p5"], side_br, side_bl])
    return FaceQuads(front, side, front_complete="p6" in p, side_complete="p7" in p)


def paper_rectangles(points: ReferencePoints, *, two_photo: bool = False) -> FaceQuads:
    """The paper's axis-aligned scan regions: front [X1, X2] x [Y1, Y3], side [X4, X5] x [Y4, Y3].

    In two-photo mode the side rectangle ends at Y7, or is as tall as the front one.
    """
    (x1, y1), (x2, _), (_, y3), (x4, y4), (x5, _) = (
        points.p1, points.p2, points.p3, points.p4, points.p5,
    )
    side_bottom = y3
    if two_photo:
        side_bottom = points.p7[1] if points.p7 is not None else y4 + (y3 - y1)
    front = np.array([[x1, y1], [x2, y1], [x2, y3], [x1, y3]], dtype=np.float64)
    side = np.array([[x4, y4], [x5, y4], [x5, side_bottom], [x4, side_bottom]], dtype=np.float64)
    return FaceQuads(front, side, front_complete=False, side_complete=False)


def validate_quad(quad: np.ndarray, name: str, image_shape: tuple[int, ...], *,
                  labels: tuple[str | None, ...] | None = None) -> None:
    """Check that a quad lies in the image, is convex, clockwise (in order) and not degenerate.

    Parameters
    ----------
    labels : tuple of 4 (str or None), optional
        The point each corner was clicked as ("p1", ...), None for a corner the clicks only
        imply (5-point mode): the message then names the clicked points, and an implied corner
        may fall outside the photo (the face runs past its border, which scanning clips).

    Raises
    ------
    InputError
        Quoting the quad's corners when the points are outside, out of order or collinear.
    """
    height, width = image_shape[:2]
    if labels is None:
        corners = ", ".join(f"({x:g},{y:g})" for x, y in quad)
        clicked = np.ones(4, dtype=bool)
    else:
        corners = ", ".join(f"{n.upper()} ({x:g},{y:g})" if n else f"the corner they imply ({x:.0f},{y:.0f})"
                            for n, (x, y) in zip(labels, quad, strict=True))
        clicked = np.array([n is not None for n in labels])
    edges = np.roll(quad, -1, axis=0) - quad
    lengths = np.linalg.norm(edges, axis=1)
    if (lengths < MIN_FACE_PX).any():
        raise InputError(f"{name} corners {corners} are closer than {MIN_FACE_PX:g} px")
    turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    sines = turns / (lengths * np.roll(lengths, -1))
    if (np.abs(sines) < 0.05).any():
        raise InputError(f"{name} corners {corners} are (nearly) collinear")
    if (sines < 0).any():
        raise InputError(
            f"{name} corners {corners} are not in order (upper-left, upper-right, lower-right, "
            "lower-left) or the face is not convex"
        )
    outside = (quad[:, 0] < -0.5) | (quad[:, 0] > width - 0.5)
    outside |= (quad[:, 1] < -0.5) | (quad[:, 1] > height - 0.5)
    if (outside & clicked).any():
        raise InputError(f"{name} corners {corners} fall outside the {width}x{height} image")


Labels = tuple[str | None, ...]


def quad_labels(quads: FaceQuads) -> tuple[Labels, Labels]:
    """Which clicked point each corner of the front and side quads is (None: implied).

    The side face's lower-left corner is always implied (by P3, or by P7 in a side photo).
    """
    front = ("p1", "p2", "p3", "p6" if quads.front_complete else None)
    return front, ("p4", "p5", "p7" if quads.side_complete else None, None)


def validate_points(points: ReferencePoints, front_shape: tuple[int, ...],
                    side_shape: tuple[int, ...]) -> None:
    """Check each clicked point lies in the image it belongs to (p4, p5, p7: the side image)."""
    for name, (x, y) in points.as_dict().items():
        height, width = (side_shape if name in ("p4", "p5", "p7") else front_shape)[:2]
        if not (-0.5 <= x <= width - 0.5 and -0.5 <= y <= height - 0.5):
            raise InputError(f"point {name} ({x:g},{y:g}) is outside the {width}x{height} image")

"""Face quadrilaterals built from the reference points, and their validation.

A quad is a float64 array of shape (4, 2) holding image positions (x, y) in the order
top-left, top-right, bottom-right, bottom-left. Edge i runs from corner i to corner i+1:
0 top, 1 right, 2 bottom, 3 left.

Point convention. P1 front upper-left, P2 front upper-right, P3 front lower-right, P6 front
lower-left. P4, P5 and P7 describe the second face by role: P4 is the front corner where the
second face's top (far) edge starts, P5 the second face's far corner next to P4, P7 its far
corner next to the other shared corner. In one photo the second face is

* ``right`` (the paper's): P4 = P2, P5 the side's far upper corner, P7 its far lower corner;
  side quad (P4, P5, P7, P3');
* ``left``: P4 = P1, P5 the side's far upper corner (left of P1), P7 its far lower corner
  (left of P6); side quad (P5, P4, P6', P7);
* ``top``: P4 = P1, P5 the top face's far corner above P1, P7 its far corner above P2; side
  quad (P5, P7, P2', P4).

(X' is the shared corner X moved by the difference between the two clicks of the corner clicked
twice, P4 - P2 or P4 - P1.) A second photo always shows the side face as a right side.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from prismcore.errors import InputError
from prismcore.spec import ReferencePoints

__all__ = ["SIDE_FACES", "FaceQuads", "SideFace", "clicked_quads", "paper_rectangles", "quad_area",
           "quad_labels", "resolve_side_face", "shared_edges", "validate_points", "validate_quad"]

MIN_FACE_PX = 4.0
SideFace = Literal["right", "left", "top"]
SIDE_FACES: tuple[SideFace, ...] = ("right", "left", "top")
_SAME_CORNER = 0.5  # P4 on P2 (or P1): under this fraction of its distance to the other one
_SHARED = {"right": (1, 3), "left": (3, 1), "top": (0, 2)}


@dataclass(frozen=True)
class FaceQuads:
    """The front and side quads as clicked (before edge refinement)."""

    front: np.ndarray
    side: np.ndarray
    front_complete: bool  # p6 was given, so the front quad is not a parallelogram guess
    side_complete: bool  # p7 was given
    side_face: SideFace = "right"  # where the second face lies (a side photo's: "right")


def shared_edges(side_face: SideFace) -> tuple[int, int]:
    """The edge index (0 top, 1 right, 2 bottom, 3 left) of the front quad and of the side quad
    that is the box edge both faces share in one photo."""
    return _SHARED[side_face]


def resolve_side_face(points: ReferencePoints, choice: str = "auto", *,
                      two_photo: bool = False) -> SideFace:
    """Which face P4, P5 (and P7) mark in one photo: `choice`, or read from the points.

    "auto": P4 on P2 -> right; P4 on P1 with P5 to its left -> left; P4 on P1 with P5 above it
    -> top. "On" is loose, as clicks are: P4 is taken for the corner it is clearly nearer to
    (under half its distance to the other one). A given choice is checked against the points the
    same way. Two photos: "right" (the side photo shows the side face; left and top are refused).

    Raises
    ------
    InputError
        When the points fit no choice, or not the one given, quoting them and what was expected.
    """
    if choice not in ("auto", *SIDE_FACES):
        raise InputError(f"side_face must be auto, right, left or top, got {choice!r}")
    if two_photo:
        if choice in ("left", "top"):
            raise InputError(f"side_face {choice!r} is for one photo: with a side photo, P4, P5 and P7 "
                             "mark the side face as photographed (its upper-left, upper-right, "
                             "lower-right corners); drop side_face or use 'right'")
        return "right"
    p = {k: np.asarray(v, dtype=np.float64) for k, v in points.as_dict().items()}
    # The front must be a face before P4 can be told to be on one of its corners: the same words
    # the front's own checks use for points on top of each other or in a line.
    if float(np.linalg.norm(p["p2"] - p["p1"])) < MIN_FACE_PX:
        raise InputError(f"front face corners P1 {_xy(p['p1'])} and P2 {_xy(p['p2'])} are closer "
                         f"than {MIN_FACE_PX:g} px")
    lower = p["p6"] if "p6" in p else p["p3"]
    (ux, uy), (vx, vy) = p["p2"] - p["p1"], lower - p["p1"]
    if abs(float(ux * vy - uy * vx)) < MIN_FACE_PX * float(np.hypot(ux, uy)):
        raise InputError(f"front face corners P1 {_xy(p['p1'])}, P2 {_xy(p['p2'])} and "
                         f"{'P6' if 'p6' in p else 'P3'} {_xy(lower)} are closer than {MIN_FACE_PX:g} px "
                         "to one line: they do not span a face")
    d1, d2 = (float(np.linalg.norm(p["p4"] - p[n])) for n in ("p1", "p2"))
    at = "p2" if d2 < _SAME_CORNER * d1 else "p1" if d1 < _SAME_CORNER * d2 else None
    found: SideFace | None = None
    why = ""
    if at == "p2":
        found = "right"
    elif at == "p1":
        # Read in the front's own axes, so a tilted photo reads the same. P7 says it best: a
        # left side's far edge P5-P7 runs down like the front's sides, a top's across like its
        # top; P5 alone (5 points) lies left of P1 or above it, which a face seen nearly
        # edge-on can blur.
        across = p["p2"] - p["p1"]
        down = (p["p6"] if "p6" in p else p["p1"] + p["p3"] - p["p2"]) - p["p1"]
        axes = np.stack([across, down], axis=1)
        lengths = np.array([np.linalg.norm(across), np.linalg.norm(down)])
        a, b = np.linalg.solve(axes, p["p5"] - p["p4"]) * lengths
        if "p7" in p:
            a7, b7 = np.linalg.solve(axes, p["p7"] - p["p5"]) * lengths
            if abs(b7) > abs(a7):
                found = "left" if b7 > 0 and a < 0 else None
            else:
                found = "top" if a7 > 0 and b < 0 else None
            if found is None:
                why = (f"P4 is on P1, so P5 {_xy(p['p5'])} and P7 {_xy(p['p7'])} must be a left side "
                       "face's far upper and lower corners (left of P1 and P6) or a top face's far "
                       "corners above P1 and P2")
        elif a < 0 and abs(a) > abs(b):
            found = "left"
        elif b < 0 and abs(b) >= abs(a):
            found = "top"
        else:
            why = (f"P4 is on P1, so P5 {_xy(p['p5'])} must lie left of it (a left side face) or "
                   "above it (a top face)")
    else:
        why = (f"P4 {_xy(p['p4'])} must be the corner P2 {_xy(p['p2'])} marks (a right side face) or "
               f"the corner P1 {_xy(p['p1'])} marks (a left side or top face)")
    if found is None:
        raise InputError(f"cannot tell which face P4, P5 and P7 mark: {why}")
    if choice != "auto" and choice != found:
        expect = {"right": "P4 on P2 and P5 right of it", "left": "P4 on P1 and P5 left of it",
                  "top": "P4 on P1 and P5 above it"}[choice]
        raise InputError(f"side_face {choice!r} expects {expect}, but P4 {_xy(p['p4'])} and "
                         f"P5 {_xy(p['p5'])} describe a {found} face")
    return found


def _xy(p: np.ndarray) -> str:
    return f"({p[0]:g},{p[1]:g})"


def quad_area(quad: np.ndarray) -> float:
    """Signed shoelace area; positive for a clockwise quad in image coordinates (y down)."""
    x, y = quad[:, 0], quad[:, 1]
    # np.roll's generality cost more than the sum: the next vertex's coordinates by slicing.
    x_next = np.concatenate((x[1:], x[:1]))
    y_next = np.concatenate((y[1:], y[:1]))
    return 0.5 * float(np.dot(x, y_next) - np.dot(x_next, y))


def clicked_quads(
    points: ReferencePoints, *, two_photo: bool, side_height_px: float | None = None,
    side_face: SideFace = "right",
) -> FaceQuads:
    """Build both face quads from the clicks.

    In single-photo mode the side face shares an edge with the front (see the module's point
    convention): a right side its lower-left corner, p3 moved by (p4 - p2); a left side its
    lower-right corner, P6 moved by (p4 - p1); a top face its lower-right corner, p2 moved by
    (p4 - p1). Without p7 its far corner is completed as a parallelogram. In two-photo mode
    without p7 the side face is taken as tall as `side_height_px` (the front's height in
    side-photo pixels), or as the front's height in pixels when that is unknown.
    """
    p = {k: np.asarray(v, dtype=np.float64) for k, v in points.as_dict().items()}
    front_bl = p["p6"] if "p6" in p else p["p1"] + p["p3"] - p["p2"]
    front = np.stack([p["p1"], p["p2"], p["p3"], front_bl])
    complete = {"front_complete": "p6" in p, "side_complete": "p7" in p}
    if not two_photo and side_face == "left":
        br = front_bl + (p["p4"] - p["p1"])
        bl = p["p7"] if "p7" in p else p["p5"] + (br - p["p4"])
        return FaceQuads(front, np.stack([p["p5"], p["p4"], br, bl]), side_face="left", **complete)
    if not two_photo and side_face == "top":
        br = p["p2"] + (p["p4"] - p["p1"])
        tr = p["p7"] if "p7" in p else p["p5"] + (br - p["p4"])
        return FaceQuads(front, np.stack([p["p5"], tr, br, p["p4"]]), side_face="top", **complete)
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


def paper_rectangles(points: ReferencePoints, *, two_photo: bool = False,
                     side_face: SideFace = "right") -> FaceQuads:
    """The paper's axis-aligned scan regions: front [X1, X2] x [Y1, Y3], side [X4, X5] x [Y4, Y3].

    In two-photo mode the side rectangle ends at Y7, or is as tall as the front one. In one
    photo a left side is [X5, X4] x [Y4, Y3] and a top face [X4, X2] x [Y5, Y4].
    """
    (x1, y1), (x2, _), (_, y3), (x4, y4), (x5, y5) = (
        points.p1, points.p2, points.p3, points.p4, points.p5,
    )
    front = np.array([[x1, y1], [x2, y1], [x2, y3], [x1, y3]], dtype=np.float64)
    if not two_photo and side_face in ("left", "top"):
        if side_face == "left":
            corners = [[x5, y4], [x4, y4], [x4, y3], [x5, y3]]
        else:
            corners = [[x4, y5], [x2, y5], [x2, y4], [x4, y4]]
        return FaceQuads(front, np.array(corners, dtype=np.float64), front_complete=False,
                         side_complete=False, side_face=side_face)
    side_bottom = y3
    if two_photo:
        side_bottom = points.p7[1] if points.p7 is not None else y4 + (y3 - y1)
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

    The side face's corner on the front's far shared corner is always implied (a right side's
    lower-left by P3, or by P7 in a side photo; a left side's lower-right by P6; a top face's
    lower-right by P2).
    """
    front = ("p1", "p2", "p3", "p6" if quads.front_complete else None)
    p7 = "p7" if quads.side_complete else None
    if quads.side_face == "left":
        return front, ("p5", "p4", None, p7)
    if quads.side_face == "top":
        return front, ("p5", p7, None, "p4")
    return front, ("p4", "p5", p7, None)


def validate_points(points: ReferencePoints, front_shape: tuple[int, ...],
                    side_shape: tuple[int, ...]) -> None:
    """Check each clicked point lies in the image it belongs to (p4, p5, p7: the side image)."""
    for name, (x, y) in points.as_dict().items():
        height, width = (side_shape if name in ("p4", "p5", "p7") else front_shape)[:2]
        if not (-0.5 <= x <= width - 0.5 and -0.5 <= y <= height - 0.5):
            raise InputError(f"point {name} ({x:g},{y:g}) is outside the {width}x{height} image")

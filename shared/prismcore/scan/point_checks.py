"""The checks on a photo spec's points that need no pixel: each point inside its photo, each
face's corners in order, convex and apart, and the second face the points mark.

`plan_scan` makes them before it measures, and the API makes the same ones when a job is
submitted (its photos' sizes are known by then), so a job the engine would refuse is refused at
once, with the engine's own words.
"""

from __future__ import annotations

import numpy as np

from prismcore.geometry.faces import (
    FaceQuads,
    Labels,
    SideFace,
    clicked_quads,
    paper_rectangles,
    quad_labels,
    resolve_side_face,
    validate_points,
    validate_quad,
)
from prismcore.spec import MmPerPx, Pinhole, ScanSpec

__all__ = ["check_points", "marked_quads", "side_height_guess"]


def side_height_guess(spec: ScanSpec) -> float | None:
    """Two photos without p7: the front's height in side-photo pixels, when the scales tell it."""
    if not spec.two_photo:
        return None
    assert spec.points is not None  # a photo spec carries its clicks
    if spec.points.p7 is not None:
        return None
    front_px = float(np.hypot(*np.subtract(spec.points.p3, spec.points.p2)))
    scale = spec.scale
    if isinstance(scale, MmPerPx) and scale.side:
        return front_px * scale.front / scale.side
    if isinstance(scale, Pinhole) and scale.side_distance_mm:
        return front_px * scale.distance_mm / scale.side_distance_mm
    return None


def check_points(spec: ScanSpec, front: tuple[int, ...], side: tuple[int, ...]) -> SideFace:
    """Check the spec's points as clicked against photos of shape `front` and `side` (height,
    width[, channels]; `side` is the front's again in single-photo mode) and read the second face
    they mark.

    Every point in its photo, then the front face alone (a bad front says so, rather than that no
    second face can be read), then the second face (`spec.side_face`, or read from the points).

    Raises
    ------
    InputError
        For a point outside its photo, a front face out of order, not convex or collapsed, or
        points that mark no second face (or not the spec's `side_face`).
    """
    assert spec.points is not None  # a photo spec carries its clicks
    validate_points(spec.points, front, side)
    if spec.method == "paper":
        validate_quad(paper_rectangles(spec.points).front, "front face", front)
    else:
        front_only = clicked_quads(spec.points, two_photo=spec.two_photo)
        validate_quad(front_only.front, "front face", front, labels=quad_labels(front_only)[0])
    return resolve_side_face(spec.points, spec.side_face, two_photo=spec.two_photo)


def marked_quads(spec: ScanSpec, side_face: SideFace, front: tuple[int, ...], side: tuple[int, ...]
                 ) -> tuple[FaceQuads, tuple[Labels | None, Labels | None]]:
    """Both faces' quads as the spec's points mark them (in the images the fit reads: undistorted
    points for a camera with distortion), checked against photos of shape `front` and `side`, and
    which point each corner is (None for the paper method's rectangles).

    Raises
    ------
    InputError
        For a face whose corners are out of order, not convex or too close together.
    """
    assert spec.points is not None  # a photo spec carries its clicks
    labels: tuple[Labels | None, Labels | None]
    if spec.method == "paper":
        marked = paper_rectangles(spec.points, two_photo=spec.two_photo, side_face=side_face)
        labels = (None, None)
    else:
        marked = clicked_quads(spec.points, two_photo=spec.two_photo,
                               side_height_px=side_height_guess(spec), side_face=side_face)
        labels = quad_labels(marked)
    validate_quad(marked.front, "front face", front, labels=labels[0])
    validate_quad(marked.side, "top face" if side_face == "top" else "side face", side, labels=labels[1])
    return marked, labels

"""A face's evidence as a pinhole would have seen it (corners, clicks and edge lines with the lens's
distortion taken out), and the samples of each of the box's edges once, from which the
distortion is read (`prismcore.geometry.lens`).
"""

from __future__ import annotations

import numpy as np

from prismcore.geometry.box_model import SECOND_FACES
from prismcore.geometry.lens import RadialDistortion, tls_line
from prismcore.geometry.perspective import (
    FaceEvidence,
)

__all__ = ["box_edge_samples", "undistort_evidence"]


def undistort_evidence(face: FaceEvidence, lens: RadialDistortion) -> FaceEvidence:
    """The face's evidence as a pinhole would have seen it: corners and clicks undistorted, each
    fitted line refitted to its undistorted samples (or, without samples, carried through two
    of its points near the face)."""
    lines: list[np.ndarray | None] = []
    for s, line in enumerate(face.lines):
        if line is None:
            lines.append(None)
            continue
        pts = face.samples[s] if s < len(face.samples) else None
        if pts is not None and len(pts) >= 2:
            lines.append(tls_line(lens.undistort(pts)))
            continue
        ends = face.corners[[s, (s + 1) % 4]]
        ends = ends - np.outer(ends @ line[:2] + line[2], line[:2])  # onto the line
        p, q = lens.undistort(ends)
        h = np.cross(np.append(p, 1.0), np.append(q, 1.0))
        lines.append(h / np.hypot(h[0], h[1]))
    samples = tuple(None if e is None else lens.undistort(e) for e in face.samples)
    return FaceEvidence(lens.undistort(face.corners), lens.undistort(face.clicked), tuple(lines), samples)


def box_edge_samples(front: FaceEvidence, side: FaceEvidence, side_face: str = "right") -> list[np.ndarray]:
    """The samples of each of the box's edges once (the edge the second face shares with the front
    is the front's)."""
    out = [e for e in front.samples if e is not None]
    if side.samples:
        out += [e for e in (side.samples[s] for s in SECOND_FACES[side_face].sides) if e is not None]
    return out

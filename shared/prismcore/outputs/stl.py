"""The measured box as a binary STL mesh (format stl, ``box.stl``): 12 triangles, millimetres,
for CAD and 3D-printing programs that import a mesh and not a STEP solid.

The box is `prismcore.outputs.part.Part`'s: ``[0, W] x [0, H] x [0, D]`` mm carried by its
placement into the frame the measurement knows (a photo's box frame, as the cloud files; a
station's board frame), so the mesh lines up with the cloud and the STEP solid. Each triangle is
wound counter-clockwise seen from outside, its normal pointing out.
"""

from __future__ import annotations

import numpy as np

from prismcore.outputs.part import Part

__all__ = ["box_stl"]

_HEADER = b"PrismCloud measured box, mm".ljust(80, b" ")  # not "solid...": that starts ASCII STL
_TRIANGLE = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


def box_stl(part: Part) -> bytes:
    """The bytes of `part`'s box as a binary STL file (80-byte header, triangle count, then per
    triangle its outward normal, three vertices and a zero attribute)."""
    size = np.array(part.size, dtype=np.float64)
    placement = np.array(part.placement, dtype=np.float64)  # [R | t]
    rotation, shift = placement[:, :3], placement[:, 3]
    centre = rotation @ (size / 2) + shift
    triangles = np.zeros(12, dtype=_TRIANGLE)
    n = 0
    for axis in range(3):
        u, v = (a for a in range(3) if a != axis)
        for side in (0.0, 1.0):
            quad = []
            for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                corner = np.zeros(3)
                corner[axis], corner[u], corner[v] = side, du, dv
                quad.append(rotation @ (corner * size) + shift)
            normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
            if np.dot(normal, quad[0] + quad[2] - 2 * centre) < 0:  # inward: wind the other way
                quad.reverse()
                normal = -normal
            normal /= np.linalg.norm(normal)
            for tri in ((quad[0], quad[1], quad[2]), (quad[0], quad[2], quad[3])):
                triangles[n]["normal"] = normal
                triangles[n]["vertices"] = tri
                n += 1
    return _HEADER + np.uint32(len(triangles)).tobytes() + triangles.tobytes()

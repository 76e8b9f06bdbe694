"""Meshes Mitsuba has no primitive for: a box with rounded edges and corners, with a UV atlas
(one cell per face) so printed labels sit on the faces, written as binary PLY."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["ATLAS", "rounded_box", "write_ply"]

# Face order and their cells in a 3 x 2 texture atlas: (+x, -x, +y, -y, +z, -z) in the box's frame.
ATLAS = {0: (0, 0), 1: (1, 0), 2: (2, 0), 3: (0, 1), 4: (1, 1), 5: (2, 1)}


def _axis_samples(half: float, r: float, n_flat: int, n_round: int) -> np.ndarray:
    """Coordinates along one side from -half to +half: dense over the roundings, sparse between."""
    if r <= 0:
        return np.linspace(-half, half, n_flat + 1)
    a = np.sin(np.linspace(0, np.pi / 2, n_round + 1)) * r  # 0..r, dense where the curve bends
    lo = -half + r - a[::-1]
    mid = np.linspace(-half + r, half - r, n_flat + 1)[1:-1]
    hi = half - r + a
    return np.concatenate([lo, mid, hi])


def rounded_box(
    size: tuple[float, float, float], radius: float, n_round: int = 6
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A box of `size` (sx, sy, sz) mm centred on the origin, edges rounded by `radius` mm.

    Each face is a grid on the sharp box, pulled onto the rounded surface: a point p goes to
    q + r n, q = p clamped to the inner box (half - r), n = (p - q) / |p - q|. Returns vertices
    (V, 3) float32, normals (V, 3), uv (V, 2) and triangles (F, 3) uint32.
    """
    half = np.asarray(size, float) / 2
    r = float(min(radius, 0.49 * half.min()))
    verts, norms, uvs, tris = [], [], [], []
    base = 0
    for face in range(6):
        axis, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
        a1, a2 = [k for k in range(3) if k != axis]
        s1 = _axis_samples(half[a1], r, 8, n_round)
        s2 = _axis_samples(half[a2], r, 8, n_round)
        g1, g2 = np.meshgrid(s1, s2, indexing="ij")
        p = np.zeros((g1.size, 3))
        p[:, axis] = sign * half[axis]
        p[:, a1] = g1.ravel()
        p[:, a2] = g2.ravel()
        inner = half - r
        q = np.clip(p, -inner, inner)
        d = p - q
        length = np.linalg.norm(d, axis=1, keepdims=True)
        n = np.where(length > 1e-12, d / np.maximum(length, 1e-12), 0.0)
        n[length[:, 0] <= 1e-12, axis] = sign
        v = q + r * n if r > 0 else p
        col, row = ATLAS[face]
        u = (col + (g1.ravel() / (2 * half[a1]) + 0.5) * 0.96 + 0.02) / 3
        w = (row + (g2.ravel() / (2 * half[a2]) + 0.5) * 0.96 + 0.02) / 2
        n1, n2 = len(s1), len(s2)
        idx = np.arange(n1 * n2).reshape(n1, n2) + base
        a, b, c, e = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
        t = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, e], -1).reshape(-1, 3)])
        # Outward winding: the triangle's normal agrees with the face's.
        tri_n = np.cross(v[t[:, 1] - base] - v[t[:, 0] - base], v[t[:, 2] - base] - v[t[:, 0] - base])
        flip = (tri_n @ np.eye(3)[axis]) * sign < 0
        t[flip] = t[flip][:, ::-1]
        verts.append(v)
        norms.append(n)
        uvs.append(np.stack([u, w], 1))
        tris.append(t)
        base += len(v)
    return (
        np.concatenate(verts).astype(np.float32),
        np.concatenate(norms).astype(np.float32),
        np.concatenate(uvs).astype(np.float32),
        np.concatenate(tris).astype(np.uint32),
    )


def write_ply(path: Path, verts: np.ndarray, normals: np.ndarray, uv: np.ndarray, tris: np.ndarray) -> None:
    """A binary little-endian PLY with positions, normals and texture coordinates."""
    vdt = np.dtype(
        [
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("nx", "<f4"),
            ("ny", "<f4"),
            ("nz", "<f4"),
            ("u", "<f4"),
            ("v", "<f4"),
        ]
    )
    vert = np.empty(len(verts), vdt)
    for i, k in enumerate("xyz"):
        vert[k] = verts[:, i]
        vert["n" + k] = normals[:, i]
    vert["u"], vert["v"] = uv[:, 0], uv[:, 1]
    fdt = np.dtype([("n", "u1"), ("i", "<u4", (3,))])
    face = np.empty(len(tris), fdt)
    face["n"] = 3
    face["i"] = tris
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(vert)}\n"
        + "".join(f"property float {k}\n" for k in ("x", "y", "z", "nx", "ny", "nz", "u", "v"))
        + f"element face {len(face)}\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(vert.tobytes())
        fh.write(face.tobytes())

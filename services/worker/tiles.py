"""A tile's two boolean masks as a small .npz: one bit per pixel (np.packbits along rows).

The tasks pass the object key of this file, never the arrays, and the merge reads the bits
back into exactly the booleans scan_band returned.
"""

from __future__ import annotations

import io

import numpy as np

from prismcore import ScanPlan
from prismcore.scan import row_tiles

__all__ = ["Tile", "pack", "plan_tiles", "unpack"]

Tile = tuple[str, int, int]  # (face name, r0, r1): rows [r0, r1) of the face's window


def plan_tiles(plan: ScanPlan, per_face: int) -> list[Tile]:
    """Every band of every face, faces in plan order and bands in row order."""
    return [(face.name, r0, r1) for face in plan.faces for r0, r1 in row_tiles(face, per_face)]


def pack(object_mask: np.ndarray, marked_mask: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, object=np.packbits(object_mask, axis=1),
                        marked=np.packbits(marked_mask, axis=1),
                        shape=np.array(object_mask.shape, dtype=np.int64))
    return buf.getvalue()


def unpack(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        rows, cols = (int(n) for n in npz["shape"])
        masks = tuple(np.unpackbits(npz[name], axis=1, count=cols).astype(bool).reshape(rows, cols)
                      for name in ("object", "marked"))
    return masks[0], masks[1]

"""Object keys of a job's files: deterministic, so a task that runs twice rewrites, never adds.

``jobs/{job}/job.json`` the final job document; under ``jobs/{job}/items/{i}/``: ``front`` and
``side`` (the inputs, copied), ``plan.json``, ``tiles/{face}-{r0}-{r1}.npz``, ``cloud.csv``,
``cloud.ply``, ``preview.ply``, ``report.json``. Items of a batch, scanned whole, have only
their outputs. A video item has ``frames.json`` (the frames selected), ``summary.json`` and per
frame ``frame_000123/`` with ``frame.png`` (the decoded frame) and the frame's outputs.
"""

from __future__ import annotations

from prism_common.storage import object_key

from prismcore.spec import frame_folder

__all__ = ["frame_key", "item_key", "job_key", "tile_id", "tile_key"]


def job_key(job_id: str, name: str) -> str:
    return object_key("jobs", job_id, name)


def item_key(job_id: str, item: int, name: str) -> str:
    return object_key("jobs", job_id, "items", item, name)


def tile_id(face: str, r0: int, r1: int) -> str:
    """The tile's name, in object keys and in the store's set of finished tiles."""
    return f"{face}-{r0}-{r1}"


def tile_key(job_id: str, item: int, face: str, r0: int, r1: int) -> str:
    return object_key("jobs", job_id, "items", item, "tiles", f"{tile_id(face, r0, r1)}.npz")


def frame_key(job_id: str, item: int, frame: int, name: str) -> str:
    return object_key("jobs", job_id, "items", item, frame_folder(frame), name)

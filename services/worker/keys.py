"""Object keys of a job's files: deterministic, so a task that runs twice rewrites, never adds.

``jobs/{job}/job.json`` the final job document; under ``jobs/{job}/items/{i}/``: ``front`` and
``side`` (the inputs, copied), ``plan.json``, ``tiles/{face}-{r0}-{r1}.npz``, ``cloud.csv``,
``cloud.ply``, ``report.json``.
"""

from __future__ import annotations

from prism_common.storage import object_key

__all__ = ["item_key", "job_key", "tile_id", "tile_key"]


def job_key(job_id: str, name: str) -> str:
    return object_key("jobs", job_id, name)


def item_key(job_id: str, item: int, name: str) -> str:
    return object_key("jobs", job_id, "items", item, name)


def tile_id(face: str, r0: int, r1: int) -> str:
    """The tile's name, in object keys and in the store's set of finished tiles."""
    return f"{face}-{r0}-{r1}"


def tile_key(job_id: str, item: int, face: str, r0: int, r1: int) -> str:
    return object_key("jobs", job_id, "items", item, "tiles", f"{tile_id(face, r0, r1)}.npz")

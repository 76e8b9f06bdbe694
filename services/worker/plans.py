"""A ScanPlan as JSON, so the plan task can hand it to the tile and finish tasks by object key.

The round trip is exact: floats are written as their shortest repr (which reads back to the
same double) and arrays keep their dtype, so tiles scanned from a reloaded plan are the very
tiles the engine would scan from the original.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from prismcore import ScanPlan, ScanSpec
from prismcore.edges import EdgeFit
from prismcore.measure import Dimensions
from prismcore.scan import FacePlan

__all__ = ["dumps", "loads", "plan_from_json", "plan_to_json"]


def _array(a: np.ndarray) -> dict[str, Any]:
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.ravel().tolist()}


def _unarray(d: dict[str, Any]) -> np.ndarray:
    return np.array(d["data"], dtype=np.dtype(d["dtype"])).reshape(d["shape"])


def _face(f: FacePlan) -> dict[str, Any]:
    return {"name": f.name, "image": f.image, "region": _array(np.asarray(f.region)),
            "marked": _array(np.asarray(f.marked)), "window": [int(w) for w in f.window],
            "method": f.method, "seed": None if f.seed is None else [float(c) for c in f.seed],
            "tolerance": float(f.tolerance)}


def _unface(d: dict[str, Any]) -> FacePlan:
    seed = None if d["seed"] is None else tuple(d["seed"])
    return FacePlan(d["name"], d["image"], _unarray(d["region"]), _unarray(d["marked"]),
                    tuple(d["window"]), d["method"], seed, d["tolerance"])  # type: ignore[arg-type]


def _edge(e: EdgeFit) -> dict[str, Any]:
    return {"line": _array(np.asarray(e.line)), "support": float(e.support),
            "rms_px": float(e.rms_px), "fitted": bool(e.fitted)}


def plan_to_json(plan: ScanPlan) -> dict[str, Any]:
    d = plan.dimensions
    return {
        "spec": plan.spec.model_dump(mode="json"),
        "faces": [_face(f) for f in plan.faces],
        "dimensions": {"width": float(d.width), "height": float(d.height), "depth": float(d.depth),
                       "unit": d.unit, "perspective": bool(d.perspective), "notes": list(d.notes),
                       "uncertainty": None if d.uncertainty is None else [float(u) for u in d.uncertainty]},
        "edges": {name: [_edge(e) for e in fits] for name, fits in plan.edges.items()},
        "image_sizes": [[int(w), int(h)] for w, h in plan.image_sizes],
        "warnings": list(plan.warnings),
        "timings_ms": {k: float(v) for k, v in plan.timings_ms.items()},
        "camera": plan.camera,  # JSON-ready already
        "fit": plan.fit,
    }


def plan_from_json(doc: dict[str, Any]) -> ScanPlan:
    d = doc["dimensions"]
    front, side = (_unface(f) for f in doc["faces"])
    return ScanPlan(
        spec=ScanSpec.model_validate(doc["spec"]),
        faces=(front, side),
        dimensions=Dimensions(d["width"], d["height"], d["depth"], d["unit"], d["perspective"],
                              tuple(d["notes"]),
                              None if d.get("uncertainty") is None else tuple(d["uncertainty"])),
        edges={name: [EdgeFit(_unarray(e["line"]), e["support"], e["rms_px"], e["fitted"])
                      for e in fits] for name, fits in doc["edges"].items()},
        image_sizes=[(w, h) for w, h in doc["image_sizes"]],
        warnings=list(doc["warnings"]),
        timings_ms=dict(doc["timings_ms"]),
        camera=dict(doc.get("camera") or {}),
        fit=dict(doc.get("fit") or {}),
    )


def dumps(plan: ScanPlan, **extra: Any) -> bytes:
    """plan.json's bytes: the plan, plus whatever the worker keeps beside it (e.g. the tiles)."""
    return json.dumps({"plan": plan_to_json(plan), **extra}).encode()


def loads(data: bytes) -> tuple[ScanPlan, dict[str, Any]]:
    doc = json.loads(data)
    return plan_from_json(doc.pop("plan")), doc

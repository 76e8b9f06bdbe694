"""write_outputs' preview: a cloud small enough to be its own preview is not put twice; the
preview then names cloud.ply, whose bytes are what preview.ply would have held. A larger cloud,
an ASCII PLY or no PLY asked for still gets a preview.ply of its own."""

from __future__ import annotations

import io
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from prismcore import ScanResult, ScanSpec, run_scan
from prismcore.outputs.sink import Writer, write_outputs
from prismcore.outputs.writers import write_ply
from prismcore.scan.cloud import PREVIEW_POINTS, Cloud, decimate
from prismsynth import Box, render_oblique_view

SCENE = render_oblique_view(Box(120.0, 80.0, 60.0), seed=5)
NAMES = ("p1", "p2", "p3", "p4", "p5")


class CountingSink:
    """Keeps each file's bytes and how many times a name was put."""

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}
        self.puts: list[str] = []

    def put(self, name: str, data: bytes | Writer, media_type: str) -> None:
        if not isinstance(data, bytes):
            buffer = io.BytesIO()
            data(buffer)
            data = buffer.getvalue()
        self.files[name] = data
        self.puts.append(name)


@pytest.fixture(scope="module")
def scanned() -> ScanResult:
    return run_scan(_spec(), SCENE.image)


def _result(scanned: ScanResult, n: int) -> ScanResult:
    """The scan's report with a cloud of `n` points."""
    rng = np.random.default_rng(n)
    cloud = Cloud(rng.normal(size=(n, 3)).astype(np.float32), rng.integers(0, 256, (n, 3), dtype=np.uint8))
    return replace(scanned, cloud=cloud)


def _spec(**extra: Any) -> ScanSpec:
    return ScanSpec.model_validate({"image": "box.png", "points": [SCENE.points[n] for n in NAMES],
                                    **extra})


def _preview_bytes(cloud: Cloud) -> bytes:
    small = decimate(cloud)
    buffer = io.BytesIO()
    write_ply(buffer, small.points, small.colors)
    return buffer.getvalue()


@pytest.mark.parametrize("n", [1, 5000, PREVIEW_POINTS])
def test_a_cloud_that_is_its_own_preview_is_put_once(scanned, n):
    result, sink = _result(scanned, n), CountingSink()
    names = write_outputs(result, sink, spec=_spec(formats=["csv", "ply"]), images=[SCENE.image],
                          preview=True, report=False)
    assert names["preview"] == names["ply"] == "cloud.ply"
    assert "preview.ply" not in sink.puts and sink.puts.count("cloud.ply") == 1
    assert sink.files["cloud.ply"] == _preview_bytes(result.cloud)  # what preview.ply would hold


@pytest.mark.parametrize(("n", "extra"), [(PREVIEW_POINTS + 1, {"formats": ["csv", "ply"]}),
                                          (5000, {"formats": ["csv", "ply"], "ply_ascii": True}),
                                          (5000, {"formats": ["csv"]})])
def test_otherwise_the_preview_is_a_file_of_its_own(scanned, n, extra):
    result, sink = _result(scanned, n), CountingSink()
    names = write_outputs(result, sink, spec=_spec(**extra), images=[SCENE.image], preview=True,
                          report=False)
    assert names["preview"] == "preview.ply" and sink.puts.count("preview.ply") == 1
    assert sink.files["preview.ply"] == _preview_bytes(result.cloud)

"""What one tracking costs per frame it reads (`prismcore.video.tracked.track_video`: decode, grey,
track; the marked frame last, so every frame before it is held), for sizing the span cap
(`TRACKED_MAX_SPAN`, ``PRISM_TRACKED_MAX_SPAN``) against the worker's task time limit.

Run: .venv/bin/python benchmarks/tracked_span.py [--size 1920x1080] [--frames 60]

A moving-camera render (prismsynth.video.moving_clip) written as MJPEG; the points of the last
frame tracked back to frame 0 (and to the middle one), process time with one OpenCV thread.

Figures of 2026-12-04 (2 cores at load 12-13), 1920x1080, 60 frames: 28.3 ms per frame read
(frame 0 reported), 27.0 ms (frames 0 and 30 reported and refined): 300 frames in about 8.5 s of
CPU, well inside the 240 s limit; memory bounds the cap instead (a held frame is 2.07 MB grey).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2

from prismcore.spec import ScanSpec
from prismcore.video.tracked import track_video
from prismsynth import Box
from prismsynth.video import moving_clip, write_video


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--frames", type=int, default=60)
    args = parser.parse_args(argv)
    w, h = map(int, args.size.split("x"))
    n = args.frames
    cv2.setNumThreads(1)
    images, truth = moving_clip(Box(120.0, 80.0, 60.0), n, image_size=(w, h), focal_px=900.0 * w / 960,
                                seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "clip.avi"
        write_video(images, path, codec="MJPG", fps=25.0)
        del images
        for reported in ([0], [0, n // 2]):
            spec = ScanSpec.model_validate({"image": str(path), "points": truth[n - 1].tolist(),
                                            "points_frame": n - 1, "frames": {"indices": reported}})
            tick = time.process_time()
            got = track_video(spec, path, reported, max_span=n)
            cpu = time.process_time() - tick
            tracked = sum(f.points is not None for f in got.values())
            print(f"{w}x{h}, {n} frames read, reported {reported} + the marked one: {1000 * cpu:.0f} ms CPU, "
                  f"{1000 * cpu / n:.1f} ms a frame; tracked {tracked} of {len(got)}; "
                  f"a held frame {w * h / 1e6:.2f} MB grey")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""What the video tests share: the clip's box and codecs, and a frame-index stamp."""

from __future__ import annotations

import numpy as np

from prismsynth import Box

CLIP_BOX = Box(120.0, 80.0, 60.0)
CLIP_FRAMES = 6
CLIP_FPS = 25.0
# (container, codec) pairs the README lists as decoding; "h264" is encoded by imageio-ffmpeg.
CODECS = [("avi", "MJPG"), ("avi", "XVID"), ("avi", "h264"), ("mp4", "mp4v"), ("mp4", "h264"),
          ("mov", "mp4v"), ("mov", "h264"), ("mkv", "MJPG")]
CODEC_IDS = [f"{ext}-{codec}" for ext, codec in CODECS]
STAMP_BITS = 10
STAMP_PX = 16


def stamp(image: np.ndarray, index: int) -> np.ndarray:
    """A copy of `image` with `index` written as black/white 16 px squares along its top-left edge
    (background there), so a decoded frame tells which frame it is."""
    out = image.copy()
    for bit in range(STAMP_BITS):
        out[:STAMP_PX, bit * STAMP_PX:(bit + 1) * STAMP_PX] = 255 if (index >> bit) & 1 else 0
    return out


def read_stamp(frame: np.ndarray) -> int:
    """The index `stamp` wrote, read from the centres of its squares."""
    q = STAMP_PX // 4
    return sum(1 << bit for bit in range(STAMP_BITS)
               if frame[q:STAMP_PX - q, bit * STAMP_PX + q:(bit + 1) * STAMP_PX - q].mean() > 128)

"""The picture of a refused zero-click measurement: what was taken for the part, and why it was
refused, so that the user sees what to change (a mat under the part, the part moved onto the
board, another light) instead of reading a reason alone."""

from __future__ import annotations

import textwrap

import cv2
import numpy as np

__all__ = ["refusal_overlay"]

_TINT = np.array([255.0, 40.0, 40.0], np.float32)  # what was taken for the part, half over the photo
_LINE_PX = 2


def refusal_overlay(photo: np.ndarray, taken: np.ndarray | None, reason: str) -> np.ndarray:
    """`photo` with what was taken for the part tinted red and outlined, and "refused: `reason`"
    written over a dark band across its top.

    Parameters
    ----------
    photo : (H, W, 3) uint8
        RGB, as the segmentation saw it (undistorted).
    taken : (H, W) bool, or None
        The pixels taken for the part (several blobs where several parts were found); None or
        empty where nothing was (no part found).
    reason : str
        The refusal's words.

    Returns
    -------
    (H, W, 3) uint8
        RGB.
    """
    out = photo.astype(np.float32)
    h, w = photo.shape[:2]
    if taken is not None and taken.any():
        out[taken] = 0.5 * out[taken] + 0.5 * _TINT
        contours, _ = cv2.findContours(taken.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        thick = max(1, round(_LINE_PX * w / 1000))
        cv2.drawContours(out, contours, -1, tuple(float(v) for v in _TINT), thick)
    scale = max(0.4, w / 1600)
    (cw, ch), base = cv2.getTextSize("x", cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    lines = textwrap.wrap("refused: " + reason, width=max(20, int(0.95 * w / cw)))
    step = ch + base + max(4, ch // 2)
    band = min(h, step * len(lines) + step // 2)
    out[:band] *= 0.35
    out = np.clip(out, 0, 255).astype(np.uint8)
    for i, line in enumerate(lines):
        cv2.putText(out, line, (max(4, w // 100), step * (i + 1)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (255, 255, 255), max(1, round(scale * 1.5)), cv2.LINE_AA)
    return out

"""What a phone's camera adds to the ideal photo: the lens's distortion (OpenCV's model), vignetting,
the JPEG round trip and a JPEG with EXIF (make, model, 35 mm equivalent focal length).
"""

from __future__ import annotations

import io
import math
from typing import cast

import cv2
import numpy as np
from PIL import Image

from prismcore.errors import InputError

from .box_geometry import _principal

__all__ = ["decode_jpeg", "distort_points", "encode_jpeg", "focal_35mm_equivalent", "vignetting_gain"]


def _jpeg_round_trip(rgb: np.ndarray, quality: int) -> np.ndarray:
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)  # OpenCV codecs expect BGR
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    decoded = cast("np.ndarray", cv2.imdecode(buf, cv2.IMREAD_COLOR))  # None only for bad bytes
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)


_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-13)


def distort_points(points: np.ndarray, camera_matrix: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Where a lens with OpenCV `distortion` puts the points an ideal pinhole (same K) puts at `points`.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Pinhole image positions (x, y), px.
    camera_matrix : np.ndarray
        (3, 3) K.
    distortion : np.ndarray
        OpenCV coefficients (k1, k2, p1, p2[, k3...]).

    Returns
    -------
    np.ndarray
        (N, 2) float64 distorted positions, px: OpenCV's forward model (``cv2.projectPoints``).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    K = np.asarray(camera_matrix, dtype=np.float64)
    # Back to normalised rays at unit depth, then projected by OpenCV with the distortion.
    rays = np.column_stack([(pts - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T, np.ones(len(pts))])
    out, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                               np.asarray(distortion, np.float64))
    return out.reshape(-1, 2)


def _undistort_grid(K: np.ndarray, dist: np.ndarray, w: int, h: int) -> np.ndarray:
    """(h, w, 2) float64: the pinhole position of every output pixel centre (OpenCV's inverse
    distortion, iterated to convergence), refusing a distortion that folds the picture."""
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    grid = np.stack([xs, ys], axis=-1).reshape(-1, 1, 2)
    und = cv2.undistortPoints(grid, K, dist, R=None, P=K, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
    # The fixed-point iteration fails silently where the model is not invertible: check the corners.
    corner = np.array([0, w - 1, (h - 1) * w, h * w - 1])
    back = distort_points(und[corner], K, dist)
    miss = float(np.abs(back - grid.reshape(-1, 2)[corner]).max())
    if not (math.isfinite(miss) and miss < 1e-4):
        raise InputError(f"distortion {dist.tolist()!r} is not invertible over a {w}x{h} image "
                         f"(the corners come back {miss:.3g} px away)")
    return und.reshape(h, w, 2)


def vignetting_gain(image_size: tuple[int, int], amount: float) -> np.ndarray:
    """(H, W) float32 gain ``1 - amount * rho^2``: 1 at the image centre, ``1 - amount`` at its corners."""
    w, h = int(image_size[0]), int(image_size[1])
    cx, cy = _principal((w, h))
    xs = (np.arange(w, dtype=np.float64) - cx) ** 2
    ys = (np.arange(h, dtype=np.float64) - cy) ** 2
    rho2 = (ys[:, None] + xs[None, :]) / (cx * cx + cy * cy)
    return (1.0 - amount * rho2).astype(np.float32)


_FULL_FRAME_DIAGONAL_MM = 43.2667  # a 36 x 24 mm frame's diagonal: the "35 mm equivalent" reference


def focal_35mm_equivalent(focal_px: float, width: int, height: int) -> float:
    """The 35 mm equivalent focal length, mm, of a focal length in px on a `width` x `height` photo
    (diagonal to diagonal: ``f_px / diagonal_px * 43.2667``)."""
    return float(focal_px) / math.hypot(width, height) * _FULL_FRAME_DIAGONAL_MM


_EXIF_IFD = 0x8769
_TAG_MAKE, _TAG_MODEL, _TAG_ORIENTATION = 0x010F, 0x0110, 0x0112
_TAG_PIXEL_X, _TAG_PIXEL_Y, _TAG_FOCAL_35 = 0xA002, 0xA003, 0xA405


def encode_jpeg(image: np.ndarray, quality: int = 90, *, focal_px: float | None = None,
                make: str | None = None, model: str | None = None) -> bytes:
    """A JPEG file of an (H, W, 3) uint8 RGB image, with the EXIF a phone writes.

    EXIF (written when any of `focal_px`, `make`, `model` is given): Make, Model, Orientation 1,
    PixelXDimension/PixelYDimension (the image's size) and, with `focal_px`,
    FocalLengthIn35mmFilm = round(`focal_35mm_equivalent`) (EXIF stores whole millimetres).
    """
    rgb = np.asarray(image)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {rgb.dtype} {rgb.shape}")
    if not 1 <= int(quality) <= 100:
        raise InputError(f"JPEG quality must be 1-100, got {quality!r}")
    pil = Image.fromarray(np.ascontiguousarray(rgb))
    options: dict[str, object] = {"quality": int(quality)}
    if focal_px is not None or make is not None or model is not None:
        exif = Image.Exif()
        if make is not None:
            exif[_TAG_MAKE] = make
        if model is not None:
            exif[_TAG_MODEL] = model
        exif[_TAG_ORIENTATION] = 1
        sub = exif.get_ifd(_EXIF_IFD)
        sub[_TAG_PIXEL_X] = rgb.shape[1]
        sub[_TAG_PIXEL_Y] = rgb.shape[0]
        if focal_px is not None:
            if not (math.isfinite(focal_px) and focal_px > 0):
                raise InputError(f"focal_px must be positive, got {focal_px!r}")
            sub[_TAG_FOCAL_35] = round(focal_35mm_equivalent(focal_px, rgb.shape[1], rgb.shape[0]))
        options["exif"] = exif.tobytes()
    buf = io.BytesIO()
    pil.save(buf, format="JPEG", **options)
    return buf.getvalue()


def decode_jpeg(data: bytes) -> np.ndarray:
    """(H, W, 3) uint8 RGB pixels of JPEG bytes (Pillow's decoder, as `encode_jpeg`'s)."""
    with Image.open(io.BytesIO(data)) as pil:
        return np.asarray(pil.convert("RGB")).copy()

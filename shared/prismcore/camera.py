"""A calibrated camera: pinhole intrinsics plus OpenCV lens distortion, and undistortion.

`prism calibrate` writes this model as ``camera.json``; a scan spec's ``camera`` carries it
(inline in a service job). Distortion is removed once, from the whole photo, before anything
else looks at it: the clicked points are moved the same way, so edge fitting and the pinhole
fit see a distortion-free image with the same intrinsics.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, PositiveInt

from prismcore.bounds import FocalPx
from prismcore.errors import InputError

if TYPE_CHECKING:
    import numpy as np

# numpy and OpenCV are imported where they are used: a job spec carries a CameraModel, and the
# API validates specs without loading them (prismcore.spec is pydantic-only).

__all__ = ["CameraModel", "undistort_image", "undistort_points"]

_RESIZE_TOLERANCE = 0.01  # relative aspect mismatch still read as the same photo resized


class CameraModel(BaseModel):
    """Intrinsics (px) and distortion of one camera at one image size.

    dist follows OpenCV's order (k1, k2, p1, p2[, k3[, k4, k5, k6]]); all zeros is a pinhole.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    fx: FocalPx
    fy: FocalPx
    cx: FiniteFloat
    cy: FiniteFloat
    dist: list[FiniteFloat] = Field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0, 0.0],
                                    min_length=4, max_length=8)
    image_width: PositiveInt
    image_height: PositiveInt
    rms_px: FiniteFloat | None = Field(default=None, description="Calibration's RMS "
                                       "reprojection error, px (informative).")
    name: str | None = Field(default=None, description="Free text: the camera, the lens.")

    def matrix(self) -> np.ndarray:
        """K, shape (3, 3), float64."""
        import numpy as np

        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def distortion(self) -> np.ndarray:
        import numpy as np

        return np.asarray(self.dist, dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return any(k != 0 for k in self.dist)

    def for_size(self, width: int, height: int) -> CameraModel:
        """The same camera for a photo of `width` x `height` px.

        A photo resized after it was taken (same aspect) scales the intrinsics; distortion
        coefficients are in normalised coordinates and stay. Any other size is refused.
        """
        if (width, height) == (self.image_width, self.image_height):
            return self
        sx, sy = width / self.image_width, height / self.image_height
        if abs(sx / sy - 1) > _RESIZE_TOLERANCE:
            raise InputError(f"the camera model is for {self.image_width}x{self.image_height} px "
                             f"photos, this one is {width}x{height}: not the same camera "
                             "or a cropped photo")
        # Pixel centres: x' + 0.5 = s (x + 0.5).
        return self.model_copy(update={
            "fx": self.fx * sx, "fy": self.fy * sy,
            "cx": (self.cx + 0.5) * sx - 0.5, "cy": (self.cy + 0.5) * sy - 0.5,
            "image_width": width, "image_height": height})


def undistort_image(image: np.ndarray, camera: CameraModel) -> np.ndarray:
    """The photo as a distortion-free pinhole camera with the same K would have taken it.

    image : (H, W, 3) RGB, uint8 or float32. Returns the same shape and dtype.
    """
    if not camera.has_distortion:
        return image
    import cv2

    K = camera.matrix()
    return cv2.undistort(image, K, camera.distortion(), None, K)


def undistort_points(points: np.ndarray, camera: CameraModel) -> np.ndarray:
    """Image (x, y) px, shape (N, 2), moved as `undistort_image` moves the pixels."""
    import cv2
    import numpy as np

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
    if not camera.has_distortion:
        return pts.reshape(-1, 2).copy()
    K = camera.matrix()
    return cv2.undistortPoints(pts, K, camera.distortion(), P=K).reshape(-1, 2)

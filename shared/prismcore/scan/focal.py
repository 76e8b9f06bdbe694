"""The camera a photo's fit starts from: the focal length in its order of trust (given > camera
model > EXIF > pooled over one camera's photos > fitted by the box fit itself), the principal
point, and a camera model's lens distortion taken out of the images and the points.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from prismcore.errors import InputError
from prismcore.spec import ReferencePoints

if TYPE_CHECKING:
    from prismcore.camera import CameraModel

__all__ = ["PRINCIPAL_MARGIN", "Focal", "PooledFocal", "camera_models", "check_principal", "prepare_images",
           "resolve_focal", "undistorted_points"]


@dataclass(frozen=True)
class PooledFocal:
    """The pooled focal length and how it was reached.

    focal_px : float
        The inverse-variance weighted mean of the estimates kept, px.
    std_px : float
        Its standard error, px, widened by the scatter of the estimates when they disagree more
        than their own errors say (Birge ratio).
    used : tuple of int
        Indices of the estimates kept; the others disagreed with the median by more than
        3 sigma (their own error combined with the estimates' robust scatter).
    """

    focal_px: float
    std_px: float
    used: tuple[int, ...]


@dataclass(frozen=True)
class Focal:
    """The focal length and principal point the fit starts from, and where they came from."""

    focal_px: float | None
    source: str  # given | camera | exif | pooled | none (fitted is decided by the fit)
    principal: list[tuple[float, float]]  # per image
    extra: dict[str, Any] = field(default_factory=dict)  # report fields of the source (a pooled std, ...)


PRINCIPAL_MARGIN = 0.5
"""How far outside the photo a principal point may lie, as a fraction of the photo's size: a
shift lens moves it a quarter of the frame at most; far outside, the perspective fit's start is
so far off that it wanders (1e6 px ran for minutes, 1e9 asked for 48 GiB)."""


def check_principal(centre: tuple[float, float], width: int, height: int, what: str) -> None:
    """Refuse a principal point (x, y) px far outside a `width` x `height` photo."""
    x, y = centre
    mx, my = PRINCIPAL_MARGIN * width, PRINCIPAL_MARGIN * height
    if not (-mx <= x <= width - 1 + mx and -my <= y <= height - 1 + my):
        raise InputError(f"{what} ({x:g}, {y:g}) px lies far outside the {width}x{height} px photo: "
                         "it is where the lens axis meets the image, near its centre "
                         f"(here about ({(width - 1) / 2:g}, {(height - 1) / 2:g}))")


def resolve_focal(images: list[np.ndarray], cameras: list[CameraModel] | None, *,
                  focal_px: float | None, principal_point: tuple[float, float] | None,
                  exif_focal_px: float | None, pooled: PooledFocal | None = None) -> Focal:
    """Order of trust: given (`focal_px`, the spec's) > camera profile > EXIF > pooled over the
    camera's photos > (fitted later). The principal point: the spec's `principal_point`, else the
    camera model's, else each image's centre."""
    centres = [((img.shape[1] - 1) / 2, (img.shape[0] - 1) / 2) for img in images]
    if cameras is not None:
        centres = [(c.cx, c.cy) for c in cameras]
    if principal_point is not None:
        centres = [principal_point] * len(images)
    for img, centre in zip(images, centres, strict=True):
        check_principal(centre, img.shape[1], img.shape[0], "principal_point" if principal_point
                         is not None else "the camera model's cx, cy")
    if focal_px is not None:
        return Focal(float(focal_px), "given", centres)
    if cameras is not None:
        return Focal(float(np.sqrt(cameras[0].fx * cameras[0].fy)), "camera", centres)
    if exif_focal_px is not None:
        return Focal(float(exif_focal_px), "exif", centres)
    if pooled is not None:
        return Focal(float(pooled.focal_px), "pooled", centres,
                      {"focal_std_px": round(pooled.std_px, 3), "pooled_photos": len(pooled.used)})
    return Focal(None, "none", centres)


def camera_models(camera: CameraModel | None, images: list[np.ndarray]) -> list[CameraModel] | None:
    """The camera model (the spec's) for each image's size, or None."""
    if camera is None:
        return None
    return [camera.for_size(img.shape[1], img.shape[0]) for img in images]


def undistorted_points(points: ReferencePoints, cameras: list[CameraModel], *,
                       two_photo: bool) -> ReferencePoints:
    """The points with each photo's lens distortion taken out (in two photos, p4, p5 and p7 are
    the side photo's)."""
    from prismcore.camera import undistort_points

    moved = {}
    for name, xy in points.as_dict().items():
        cam = cameras[1 if two_photo and name in ("p4", "p5", "p7") else 0]
        moved[name] = tuple(float(v) for v in undistort_points(np.array([xy]), cam)[0])
    return ReferencePoints.model_validate(moved)


def prepare_images(camera: CameraModel | None, images: list[np.ndarray]) -> list[np.ndarray]:
    """The images the plan's coordinates refer to: undistorted when the camera model (the spec's)
    has lens distortion, else the images themselves. Scan the tiles and finish on these.

    images : list of (H, W, 3) RGB arrays, front first.
    """
    cameras = camera_models(camera, images)
    if cameras is None or not cameras[0].has_distortion:
        return images
    from prismcore.camera import undistort_image

    return [undistort_image(img, cam) for img, cam in zip(images, cameras, strict=True)]

"""A camera's lens distortion taken out of its photos: the maps built once per camera and kept
for the next photo of the same camera (a station measures many)."""

from __future__ import annotations

import cv2
import numpy as np

from prismcore.camera import CameraModel

__all__ = ["Undistorter", "undistorter"]


class Undistorter:
    """The maps that remove a camera's lens distortion, built once per camera."""

    def __init__(self, camera: CameraModel) -> None:
        self.camera = camera
        self.K = camera.matrix()
        size = (camera.image_width, camera.image_height)
        self.maps = (
            cv2.initUndistortRectifyMap(self.K, camera.distortion(), None, self.K, size, cv2.CV_16SC2)
            if camera.has_distortion
            else None
        )

    def image(self, image: np.ndarray) -> np.ndarray:
        if self.maps is None:
            return image
        return cv2.remap(image, self.maps[0], self.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


_UNDISTORTERS: dict[str, Undistorter] = {}


def undistorter(camera: CameraModel) -> Undistorter:
    key = camera.model_dump_json()
    # the one kept is read once and returned as read: another thread (the API verifies stations
    # in threads) may clear the cache for its own camera meanwhile
    kept = _UNDISTORTERS.get(key)
    if kept is None:
        kept = Undistorter(camera)
        _UNDISTORTERS.clear()
        _UNDISTORTERS[key] = kept
    return kept

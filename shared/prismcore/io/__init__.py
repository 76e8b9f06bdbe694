"""Reading inputs: photos (decoded safely to RGB), their EXIF focal length, videos' frames, and
which container a file is, from its first bytes.

Names are imported on first use (`prismcore._lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prismcore._lazy import lazy_exports

__all__ = [
    "CameraExif",
    "ImageInfo",
    "VideoInfo",
    "exif_focal",
    "iter_frames",
    "load_image",
    "probe_image",
    "probe_video",
    "read_camera_exif",
    "video_container",
]

_EXPORTS = {
    "CameraExif": "exif",
    "ImageInfo": "images",
    "VideoInfo": "video_decode",
    "exif_focal": "exif",
    "iter_frames": "video_decode",
    "load_image": "images",
    "probe_image": "images",
    "probe_video": "video_decode",
    "read_camera_exif": "exif",
    "video_container": "containers",
}

if TYPE_CHECKING:
    from prismcore.io.containers import video_container
    from prismcore.io.exif import CameraExif, exif_focal, read_camera_exif
    from prismcore.io.images import ImageInfo, load_image, probe_image
    from prismcore.io.video_decode import VideoInfo, iter_frames, probe_video

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

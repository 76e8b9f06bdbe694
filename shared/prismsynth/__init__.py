"""prismsynth: synthetic photos and videos of a box of known size, ground truth for the engine.

Used by the tests, the benchmarks and `prism sample`; the engine (`prismcore`) never imports
it. `render` draws single photos (ideal pinhole or phone-like; its parts `models`, `box_geometry`,
`textures`, `phone`), `photo_like` whole phone-like scenes from a seed, `video` short clips.
"""

from __future__ import annotations

from .models import DEFAULT_STYLE, Box, CameraExif, Realism, Scene, Style
from .phone import decode_jpeg, distort_points, encode_jpeg, focal_35mm_equivalent, vignetting_gain
from .photo_like import PhotoLikeScene, photo_like_scene
from .render import render_front_view, render_oblique_view, render_side_view, save_image
from .video import render_clip, write_video
from .views import photo_like_views

__all__ = [
    "DEFAULT_STYLE",
    "Box",
    "CameraExif",
    "PhotoLikeScene",
    "Realism",
    "Scene",
    "Style",
    "decode_jpeg",
    "distort_points",
    "encode_jpeg",
    "focal_35mm_equivalent",
    "photo_like_scene",
    "photo_like_views",
    "render_clip",
    "render_front_view",
    "render_oblique_view",
    "render_side_view",
    "save_image",
    "vignetting_gain",
    "write_video",
]

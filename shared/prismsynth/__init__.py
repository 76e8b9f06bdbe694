"""prismsynth: synthetic photos and videos of a box of known size, ground truth for the engine.

Used by the tests, the benchmarks and `prism sample`; the engine (`prismcore`) never imports
it. `render` draws single photos (ideal pinhole or phone-like), `video` short clips of them.
"""

from __future__ import annotations

from .render import (
    DEFAULT_STYLE,
    Box,
    CameraExif,
    PhotoLikeScene,
    Realism,
    Scene,
    Style,
    decode_jpeg,
    distort_points,
    encode_jpeg,
    focal_35mm_equivalent,
    photo_like_scene,
    render_front_view,
    render_oblique_view,
    render_side_view,
    save_image,
    vignetting_gain,
)
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

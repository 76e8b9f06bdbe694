"""prismpbr: physically based photos of parts on a printed board, for measuring the zero-click
modes on scenes they were never tuned to.

A second, independent scene generator beside `prismsynth`: it shares no light model with it
(path traced by Mitsuba 3: area lights, a window, ambient light, soft shadows, interreflection,
glossy and metal parts that mirror the board), and draws its scenes from two `Settings`
(`DEVELOPMENT` to tune on, `REPORT` to report). `layout` says what is in a scene, `render`
makes the photo, `camera` the lens, `meshes` the rounded box, `textures` the surfaces. Only
tests and benchmarks use it; the engine never imports it.
"""

from __future__ import annotations

from .camera import LensCamera, look_at
from .layout import DEVELOPMENT, REPORT, SETS, Part, Scene, Settings, handheld_scene, station_scenes
from .render import GENERATOR_VERSION, cache_dir, render_scene
from .visibility import board_corners_shown

__all__ = [
    "DEVELOPMENT",
    "GENERATOR_VERSION",
    "REPORT",
    "SETS",
    "LensCamera",
    "Part",
    "Scene",
    "Settings",
    "board_corners_shown",
    "cache_dir",
    "handheld_scene",
    "look_at",
    "render_scene",
    "station_scenes",
]

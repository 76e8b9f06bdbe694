"""Video fixtures: short clips of a box of known size, rendered once and encoded per codec."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from video_clips import CLIP_BOX, CLIP_FPS, CLIP_FRAMES, stamp

from prismsynth import Scene, render_clip, write_video


@pytest.fixture(scope="session")
def clip_scenes() -> list[Scene]:
    """CLIP_FRAMES renders of CLIP_BOX, 640x512, the camera swaying by up to half a degree."""
    return render_clip(CLIP_BOX, CLIP_FRAMES, seed=3)


@pytest.fixture(scope="session")
def make_clip(clip_scenes, tmp_path_factory) -> Callable[[str, str], Path]:
    """make_clip(container, codec) -> the path of the clip encoded so (made once per session)."""
    folder = tmp_path_factory.mktemp("clips")
    made: dict[tuple[str, str], Path] = {}

    def make(ext: str, codec: str) -> Path:
        if (ext, codec) not in made:
            path = folder / f"clip_{codec}.{ext}"
            write_video((s.image for s in clip_scenes), path, codec=codec, fps=CLIP_FPS)
            made[ext, codec] = path
        return made[ext, codec]

    return make


@pytest.fixture(scope="session")
def make_long_clip(clip_scenes, tmp_path_factory) -> Callable[[str, str, int], Path]:
    """make_long_clip(container, codec, frames): the clip's frames cycled, each stamped with its
    index (made once per session and arguments)."""
    folder = tmp_path_factory.mktemp("long_clips")
    made: dict[tuple[str, str, int], Path] = {}

    def make(ext: str, codec: str, frames: int) -> Path:
        if (ext, codec, frames) not in made:
            path = folder / f"long_{codec}_{frames}.{ext}"
            images = (stamp(clip_scenes[i % len(clip_scenes)].image, i) for i in range(frames))
            write_video(images, path, codec=codec, fps=CLIP_FPS)
            made[ext, codec, frames] = path
        return made[ext, codec, frames]

    return make

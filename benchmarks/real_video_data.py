"""OpenCV's real-time pose tutorial video of a cookie box, and our hand marks on it.

The video ships compressed in Debian's ``opencv-doc`` package (``opencv4/html/box.mp4.gz``,
640x480, 455 frames at 29.97 fps); it is not ours to commit, so it is unpacked into a gitignored
cache folder on first use. The marks (``data/opencv_box_marks.json``) are committed: per frame,
the seven reference points in the engine's order and which box dimension each face shows.

The box is the tutorial's ``box.ply`` (samples/cpp/tutorial_code/calib3d/real_time_pose_estimation/
Data/box.ply, vertices in cm: x 0..18.9, y 0..25.8, z 0..7.5), i.e. 258 x 189 x 75 mm.
"""

from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / ".cache" / "opencv-box"
MARKS = Path(__file__).resolve().parent / "data" / "opencv_box_marks.json"
DOC_ROOT = Path("/usr/share/doc/opencv-doc")
INSTALL_HINT = "install Debian's opencv-doc package (apt-get install opencv-doc), which ships box.mp4.gz"

BOX_MM = {"long": 258.0, "short": 189.0, "height": 75.0}
"""The box's three edge lengths, mm, named by the faces of the video: the long edge, the short
edge (both of the lid) and the height."""

TUTORIAL_CAMERA = {"fx": 640 * 55 / 22.3, "fy": 480 * 55 / 14.9, "cx": 320.0, "cy": 240.0,
                   "image_width": 640, "image_height": 480}
"""The intrinsics the tutorial's main_detection.cpp uses for this video ("UVC WEBCAM": f = 55 mm,
sensor 22.3 x 14.9 mm, 640x480): fx = 1578.5, fy = 1771.8 px. A nominal guess, not a calibration
(fx != fy for square pixels); the box's own fit disagrees with it by a factor of about 2.5."""


def find_video_gz(doc_root: Path = DOC_ROOT) -> Path:
    """The packaged ``box.mp4.gz``; FileNotFoundError naming the package when it is missing."""
    usual = doc_root / "opencv4" / "html" / "box.mp4.gz"
    if usual.is_file():
        return usual
    found = sorted(doc_root.rglob("box.mp4*")) if doc_root.is_dir() else []
    if not found:
        raise FileNotFoundError(f"box.mp4.gz not found under {doc_root}: {INSTALL_HINT}")
    return found[0]


def video_path(cache: Path = CACHE, doc_root: Path = DOC_ROOT) -> Path:
    """The unpacked video in ``cache`` (gunzipped there on first use)."""
    target = cache / "box.mp4"
    if target.is_file() and target.stat().st_size > 0:
        return target
    source = find_video_gz(doc_root)
    cache.mkdir(parents=True, exist_ok=True)
    partial = target.with_suffix(".part")
    if source.suffix == ".gz":
        with gzip.open(source, "rb") as src, partial.open("wb") as dst:
            shutil.copyfileobj(src, dst)
    else:
        shutil.copyfile(source, partial)
    partial.replace(target)  # never leave a truncated box.mp4 for the next run to trust
    return target


def read_frames(path: Path, indices: list[int]) -> dict[int, np.ndarray]:
    """Decode the given frame indices (sequentially, as seeking in this H.264 file is not exact).

    Returns
    -------
    dict of int to ndarray, shape (480, 640, 3), uint8, RGB.
    """
    wanted = set(indices)
    out: dict[int, np.ndarray] = {}
    cap = cv2.VideoCapture(str(path))
    try:
        index = 0
        while wanted - out.keys():
            ok, bgr = cap.read()
            if not ok:
                break
            if index in wanted:
                out[index] = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            index += 1
    finally:
        cap.release()
    missing = sorted(wanted - out.keys())
    if missing:
        raise ValueError(f"frames {missing} not in {path} ({index} frames decoded)")
    return out


def load_marks(path: Path = MARKS) -> dict:
    """The marks file as a dict (see its ``convention`` entry)."""
    return json.loads(path.read_text())


def truth_mm(frame: dict) -> dict[str, float]:
    """The true width, height and depth (mm) of one marked frame's faces."""
    return {axis: BOX_MM[frame["truth"][axis]] for axis in ("width", "height", "depth")}


def points_of(frame: dict) -> list[list[float]]:
    """The frame's seven points in the engine's order P1..P7."""
    return [list(frame["points"][f"P{k}"]) for k in range(1, 8)]

"""A refused zero-click photo shows what was taken for the part: `prism scan --station` writes the
overlay (the blobs tinted, the reason across the top) in the output folder and names it in its
one line, exit 2. Checked against where the parts truly are in the photo."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from prismcore.camera import CameraModel
from prismcore.station import calibrate_station
from prismsynth.station import station_scene, station_setup

PRISM = Path(sys.executable).with_name("prism")


def _save(path: Path, rgb: np.ndarray) -> None:
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


@pytest.fixture(scope="module")
def refused(tmp_path_factory) -> tuple[Path, np.ndarray, np.ndarray]:
    """A station, its empty support, and a photo with two parts: the second pasted from another
    photo on the same station where it differs from the support. Returns (folder, where the two
    parts are (H, W) bool, the plate), both undistorted as the overlay shows them."""
    d = tmp_path_factory.mktemp("refusal")
    setup = station_setup(11)
    plate = station_scene(11, setup, parts=0).plate
    su = setup
    camera = CameraModel(fx=su.K[0, 0], fy=su.K[1, 1], cx=su.K[0, 2], cy=su.K[1, 2],
                         dist=[float(v) for v in su.dist], image_width=su.image_size[0],
                         image_height=su.image_size[1])
    (d / "station.json").write_text(calibrate_station(setup.board, plate, camera=camera, plate=plate)
                                    .model_dump_json())
    scenes = [station_scene(seed, setup, max_size_mm=60, nudge=False) for seed in (21, 23)]
    parts = []  # each part's true silhouette: the hull of its box's corners through the camera
    for sc in scenes:
        assert sc.box is not None
        # in the undistorted photo, as the segmentation sees it and the overlay shows it
        px = cv2.projectPoints(sc.box.corners(), cv2.Rodrigues(su.R)[0], su.t, su.K, None)[0]
        hull = np.zeros(plate.shape[:2], np.uint8)
        cv2.fillConvexPoly(hull, cv2.convexHull(px.astype(np.int32)), 1)
        parts.append(hull > 0)
    assert not (parts[0] & parts[1]).any()  # two places on the support
    both = scenes[0].photo.copy()
    both[parts[1]] = scenes[1].photo[parts[1]]
    _save(d / "two.jpg", both)
    _save(d / "empty.jpg", plate)
    return d, parts[0] | parts[1], cv2.undistort(plate, su.K, su.dist)


def _run(d: Path, photo: str, out: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(PRISM), "scan", photo, "--station", "station.json", "--out", out], cwd=d,
                          capture_output=True, text=True, timeout=300)


def test_two_parts_refused_show_both_tinted_and_the_reason(refused) -> None:
    d, where, _ = refused
    run = _run(d, "two.jpg", "out")
    assert run.returncode == 2, run.stdout + run.stderr
    said = (run.stdout + run.stderr).strip().splitlines()
    assert len(said) == 1 and "2 parts found" in said[0] and "shows what was taken for the part" in said[0]
    overlay = cv2.cvtColor(cv2.imread(str(d / "out/overlay.jpg")), cv2.COLOR_BGR2RGB).astype(int)
    red = (overlay[..., 0] - overlay[..., 1] > 60) & (overlay[..., 0] - overlay[..., 2] > 60)
    # each part's silhouette tinted, a few pixels in from its edge (the outline found is the
    # segmentation's own), and the support away from both not
    n, labels = cv2.connectedComponents(cv2.erode(where.astype(np.uint8), np.ones((7, 7), np.uint8)))
    assert n == 3
    for i in (1, 2):
        assert red[labels == i].mean() > 0.9, (i, red[labels == i].mean())
    away = cv2.dilate(where.astype(np.uint8), np.ones((61, 61), np.uint8)) == 0
    assert red[away].mean() < 0.01
    assert not (d / "out/report.json").exists()


def test_no_part_refused_shows_the_photo_with_nothing_taken(refused) -> None:
    d, _, plate = refused
    run = _run(d, "empty.jpg", "empty")
    assert run.returncode == 2, run.stdout + run.stderr
    assert "no part found" in run.stdout + run.stderr
    overlay = cv2.cvtColor(cv2.imread(str(d / "empty/overlay.jpg")), cv2.COLOR_BGR2RGB).astype(int)
    band = int(np.argmax(np.abs(overlay - plate.astype(int)).mean(axis=(1, 2)) < 6))  # the reason's band ends
    assert band > 10
    below = np.abs(overlay[band + 5 :] - plate[band + 5 :].astype(int)).mean()
    assert below < 6, below  # under the band, the photo as it was: nothing tinted

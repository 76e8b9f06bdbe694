"""A station's calibration: the camera (intrinsics, lens) and the support plane it looks at.

The station's frame is the frame of the board lying flat on the support in the plane photo:
x, y on the support, z = 0 on it, heights reported positive above it. The plate (a photo of
the empty support from the working position) is kept as the background model.
"""

from __future__ import annotations

import base64
from collections.abc import Sequence

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from prismcore.camera import CameraModel
from prismcore.errors import InputError
from prismcore.station.board import BoardSpec, BoardView, find_board_corners
from prismcore.station.verify import Verification

__all__ = [
    "MAX_RMS_PX",
    "MIN_PLANE_CORNERS",
    "MIN_VIEWS",
    "PlanePose",
    "Station",
    "board_pose",
    "calibrate_station",
    "decode_plate",
    "encode_plate",
]

MIN_VIEWS = 3  # Zhang's method: two constraints a view on five intrinsics
MIN_VIEW_CORNERS = 8  # a ChArUco view with fewer is left out of the intrinsics
MIN_PLANE_CORNERS = 12  # the plane's pose from fewer is refused
MAX_RMS_PX = 1.0  # a calibration (or plane fit) whose corners miss by more is refused


class PlanePose(BaseModel):
    """The support plane's pose: board frame -> camera frame (x_cam = R @ x_board + t)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    rvec: list[float] = Field(min_length=3, max_length=3, description="Rodrigues vector.")
    tvec: list[float] = Field(min_length=3, max_length=3, description="Translation, mm.")
    rms_px: float = Field(description="RMS of the plane photo's corners about the fitted pose, px.")
    corners: int = Field(description="Board corners the pose was fitted to.")

    def rotation(self) -> np.ndarray:
        return cv2.Rodrigues(np.asarray(self.rvec, np.float64))[0]

    def translation(self) -> np.ndarray:
        return np.asarray(self.tvec, np.float64)

    def camera_centre(self) -> np.ndarray:
        """The camera's centre in the board frame, mm (z < 0: above the support)."""
        return np.asarray(-self.rotation().T @ self.translation(), dtype=np.float64)


class Station(BaseModel):
    """station.json: everything `prism scan --station` needs besides the photo."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    version: int = 1
    board: BoardSpec
    camera: CameraModel
    plane: PlanePose
    calibration: dict[str, object] = Field(
        default_factory=dict,
        description=("How the intrinsics were found: source (photos or camera), rms_px, views, corners."),
    )
    plate_png: str | None = Field(default=None, description="The empty support, base64 PNG (RGB).")
    verification: Verification | None = Field(
        default=None, description="The last verification with a reference part (prism station verify)."
    )

    def plate(self) -> np.ndarray | None:
        return None if self.plate_png is None else decode_plate(self.plate_png)


def encode_plate(image: np.ndarray) -> str:
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 3])
    if not ok:
        raise InputError("the plate photo could not be encoded")
    return base64.b64encode(data.tobytes()).decode("ascii")


def decode_plate(text: str) -> np.ndarray:
    data = np.frombuffer(base64.b64decode(text), np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    if image is None:
        raise InputError("station.json: its plate is not a PNG image")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def board_pose(view: BoardView, camera: CameraModel) -> PlanePose:
    """The board's pose from its corners in one photo (PnP, refined by Levenberg-Marquardt)."""
    obj = view.object_points.astype(np.float64)
    img = view.image_points.astype(np.float64)
    K, dist = camera.matrix(), camera.distortion()
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise InputError("the board's pose could not be fitted to its corners")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    proj = cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=1))))
    return PlanePose(
        rvec=[float(v) for v in rvec.ravel()],
        tvec=[float(v) for v in tvec.ravel()],
        rms_px=rms,
        corners=len(view),
    )


def _intrinsics(
    views: Sequence[tuple[str, BoardView]], size: tuple[int, int]
) -> tuple[CameraModel, dict[str, object]]:
    used = [(n, v) for n, v in views if len(v) >= MIN_VIEW_CORNERS]
    if len(used) < MIN_VIEWS:
        raise InputError(
            f"the board was found (at least {MIN_VIEW_CORNERS} corners) in {len(used)} "
            f"of {len(views)} calibration photos; at least {MIN_VIEWS} are needed, the "
            "board tilted differently in each"
        )
    obj = [v.object_points.astype(np.float32) for _, v in used]
    img = [v.image_points.astype(np.float32) for _, v in used]
    try:
        rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None)
    except cv2.error as exc:
        raise InputError(
            f"calibration of {len(used)} views failed: degenerate views ({str(exc).strip().splitlines()[-1]})"
        ) from None
    dist = np.ravel(dist)
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist))):
        raise InputError(
            "calibration is degenerate (non-finite result); photograph the board at several tilts"
        )
    camera = CameraModel(
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        dist=[float(v) for v in dist],
        image_width=size[0],
        image_height=size[1],
        rms_px=float(rms),
    )
    info = {
        "source": "photos",
        "rms_px": float(rms),
        "views": [n for n, _ in used],
        "views_left_out": [n for n, v in views if len(v) < MIN_VIEW_CORNERS],
        "corners": int(sum(len(v) for _, v in used)),
    }
    return camera, info


def calibrate_station(
    board: BoardSpec,
    plane_image: np.ndarray,
    calibration_images: Sequence[tuple[str, np.ndarray]] = (),
    *,
    camera: CameraModel | None = None,
    plate: np.ndarray | None = None,
    plane_name: str = "the plane photo",
) -> Station:
    """Calibrate a station.

    Parameters
    ----------
    board : BoardSpec
    plane_image : ndarray, shape (H, W, 3), uint8
        The board lying flat on the support, camera in its working position. Also a calibration
        view when `camera` is None.
    calibration_images : sequence of (str, ndarray)
        (name, RGB photo) of the board in several poses, same camera and size.
    camera : CameraModel, optional
        Known intrinsics; then `calibration_images` are not needed.
    plate : ndarray, shape (H, W, 3), uint8, optional
        The empty support from the working position (the background model).

    Raises
    ------
    InputError
        Photos of another size, too few views or corners, an RMS over ``MAX_RMS_PX``, a plane
        photo without enough of the board, a plate of another size.
    """
    h, w = plane_image.shape[:2]
    for name, image in calibration_images:
        if image.shape[:2] != (h, w):
            raise InputError(
                f"{name} is {image.shape[1]}x{image.shape[0]} px but {plane_name} is {w}x{h}: "
                "one camera at one size"
            )
    if plate is not None and plate.shape[:2] != (h, w):
        raise InputError(f"the plate is {plate.shape[1]}x{plate.shape[0]} px but {plane_name} is {w}x{h}")
    plane_view = find_board_corners(plane_image, board)
    if plane_view is None or len(plane_view) < MIN_PLANE_CORNERS:
        found = 0 if plane_view is None else len(plane_view)
        raise InputError(
            f"{plane_name}: {found} board corners found, at least {MIN_PLANE_CORNERS} are "
            "needed for the support plane (the board flat on the support, in view)"
        )
    if camera is None:
        views = [(plane_name, plane_view)]
        for name, image in calibration_images:
            view = find_board_corners(image, board)
            views.append(
                (
                    name,
                    view
                    if view is not None
                    else BoardView(np.empty((0, 2)), np.empty((0, 3)), np.empty(0, int)),
                )
            )
        camera, info = _intrinsics(views, (w, h))
        if camera.rms_px is not None and camera.rms_px > MAX_RMS_PX:
            raise InputError(
                f"calibration RMS {camera.rms_px:.2f} px is over {MAX_RMS_PX} px: blurred "
                "photos, a board that is not flat, or the wrong board.json"
            )
    else:
        camera = camera.for_size(w, h)
        info = {"source": "camera", "rms_px": camera.rms_px}
    plane = board_pose(plane_view, camera)
    if plane.rms_px > MAX_RMS_PX:
        raise InputError(
            f"{plane_name}: the board's corners miss its fitted plane by {plane.rms_px:.2f} px "
            f"RMS (over {MAX_RMS_PX} px): the board is not flat, or the camera model is not "
            "this camera's"
        )
    if plane.camera_centre()[2] >= 0:
        raise InputError(f"{plane_name}: the board is seen from below; lay it face up on the support")
    return Station(
        board=board,
        camera=camera,
        plane=plane,
        calibration=info,
        plate_png=None if plate is None else encode_plate(plate),
    )

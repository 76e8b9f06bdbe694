"""The face of `prismcore.io`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .containers import HEAD_BYTES as HEAD_BYTES
from .containers import video_container as video_container
from .exif import EXIF_HEAD_BYTES as EXIF_HEAD_BYTES
from .exif import CameraExif as CameraExif
from .exif import exif_focal as exif_focal
from .exif import read_camera_exif as read_camera_exif
from .images import ImageInfo as ImageInfo
from .images import load_image as load_image
from .images import probe_image as probe_image
from .images import sniff_format as sniff_format
from .video_decode import VideoInfo as VideoInfo
from .video_decode import is_video as is_video
from .video_decode import iter_frames as iter_frames
from .video_decode import probe_video as probe_video

"""The face of `prismcore.video`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .frame_select import viewing_spread as viewing_spread
from .frames import frame_spec as frame_spec
from .frames import probe_video as probe_video
from .frames import select_frames as select_frames
from .point_search import FrameSearch as FrameSearch
from .pooling import PooledFocal as PooledFocal
from .pooling import focal_estimate as focal_estimate
from .pooling import pool_focal as pool_focal
from .span import points_frame_problem as points_frame_problem
from .span import span_problem as span_problem
from .span import tracked_span as tracked_span
from .summary import DIMENSIONS as DIMENSIONS
from .summary import frame_info as frame_info
from .summary import summarize as summarize
from .summary import video_summary as video_summary
from .track_refine import box_refiner as box_refiner
from .tracked import Tracking as Tracking
from .tracked import check_points_frame as check_points_frame
from .tracked import check_points_frame_span as check_points_frame_span
from .tracked import fit_tracked as fit_tracked
from .tracked import joint_frames as joint_frames
from .tracked import per_frame_spec as per_frame_spec
from .tracked import track_video as track_video
from .tracked import tracked_frame_spec as tracked_frame_spec
from .tracked import tracked_json as tracked_json
from .tracked import tracked_views as tracked_views
from .tracking import track_points as track_points

"""The face of `prismcore.scan`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .cloud import Cloud as Cloud
from .cloud import assemble as assemble
from .cloud import decimate as decimate
from .colour_scan import FacePlan as FacePlan
from .colour_scan import FaceScan as FaceScan
from .colour_scan import merge_bands as merge_bands
from .colour_scan import row_tiles as row_tiles
from .colour_scan import scan_band as scan_band
from .focal import prepare_images as prepare_images
from .measure import Dimensions as Dimensions
from .measure import measure_affine as measure_affine
from .measure import measure_perspective as measure_perspective
from .pipeline import ScanPlan as ScanPlan
from .pipeline import ScanResult as ScanResult
from .pipeline import finish_scan as finish_scan
from .pipeline import plan_scan as plan_scan
from .pipeline import run_scan as run_scan
from .pipeline import scan_face as scan_face
from .point_checks import check_points as check_points
from .point_checks import marked_quads as marked_quads
from .spacing import thin_to_count as thin_to_count
from .spacing import thin_to_spacing as thin_to_spacing

"""The face of `prismcore`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from ._version import __version__ as __version__
from .camera import CameraModel as CameraModel
from .errors import InputError as InputError
from .errors import PartRefusedError as PartRefusedError
from .io.images import load_image as load_image
from .locate.search import find_points as find_points
from .multiview.joint import fit_views as fit_views
from .outputs.writers import write_csv as write_csv
from .outputs.writers import write_ply as write_ply
from .report import ScanReport as ScanReport
from .scan.cloud import Cloud as Cloud
from .scan.measure import Dimensions as Dimensions
from .scan.pipeline import ScanPlan as ScanPlan
from .scan.pipeline import ScanResult as ScanResult
from .scan.pipeline import finish_scan as finish_scan
from .scan.pipeline import plan_scan as plan_scan
from .scan.pipeline import run_scan as run_scan
from .scan.pipeline import scan_face as scan_face
from .spec import ReferencePoints as ReferencePoints
from .spec import ScanSpec as ScanSpec
from .spec import parse_points as parse_points
from .station.calibrate import Station as Station

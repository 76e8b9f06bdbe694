"""The face of `prismcore.station`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .board import PAPER_MM as PAPER_MM
from .board import BoardSpec as BoardSpec
from .board import board_image as board_image
from .board import default_board as default_board
from .board import find_board_corners as find_board_corners
from .calibrate import Station as Station
from .calibrate import calibrate_station as calibrate_station
from .capability import capability as capability
from .capability import capability_lines as capability_lines
from .certify import parse_reference as parse_reference
from .certify import verification_status as verification_status
from .certify import verify_measured as verify_measured
from .certify import verify_station as verify_station
from .measure import StationMeasurement as StationMeasurement
from .measure import measure_on_station as measure_on_station
from .scan import StationScan as StationScan
from .scan import scan_on_board as scan_on_board
from .scan import scan_on_station as scan_on_station
from .scan import station_report as station_report
from .verify import Verification as Verification
from .verify import check_count as check_count
from .verify import verify_placements as verify_placements

"""The face of `prismcore.geometry`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .box_model import SECOND_FACES as SECOND_FACES
from .box_model import SecondFace as SecondFace
from .box_model import camera_matrix as camera_matrix
from .calibration import Calibration as Calibration
from .calibration import calibrate as calibrate
from .calibration import calibrate_images as calibrate_images
from .calibration import find_board as find_board
from .edges import EdgeFit as EdgeFit
from .edges import refine_quad as refine_quad
from .faces import FaceQuads as FaceQuads
from .faces import clicked_quads as clicked_quads
from .faces import resolve_side_face as resolve_side_face
from .faces import validate_points as validate_points
from .perspective import BoxFit as BoxFit
from .perspective import fit_box as fit_box
from .perspective import fit_rectangle as fit_rectangle
from .rounding import RadiusEstimate as RadiusEstimate
from .rounding import estimate_edge_radius as estimate_edge_radius

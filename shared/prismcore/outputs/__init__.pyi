"""The face of `prismcore.outputs`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .drawing import inspection_sheet as inspection_sheet
from .drawing_files import drawing_dxf as drawing_dxf
from .drawing_files import drawing_pdf as drawing_pdf
from .drawing_files import drawing_svg as drawing_svg
from .glb import box_glb as box_glb
from .las import write_las as write_las
from .overlay import draw_overlay as draw_overlay
from .overlay_report import given_dimension as given_dimension
from .overlay_report import overlay_from_report as overlay_from_report
from .overlay_report import points_found as points_found
from .part import Part as Part
from .part import part_from_report as part_from_report
from .refusal import refusal_overlay as refusal_overlay
from .sink import Sink as Sink
from .sink import Writer as Writer
from .sink import overlay_media_type as overlay_media_type
from .sink import report_bytes as report_bytes
from .sink import write_outputs as write_outputs
from .sink import write_part_files as write_part_files
from .step import step_bytes as step_bytes
from .step import step_metadata as step_metadata
from .stl import box_stl as box_stl
from .writers import DEFAULT_OVERLAY_FORMAT as DEFAULT_OVERLAY_FORMAT
from .writers import encode_overlay as encode_overlay
from .writers import overlay_name as overlay_name
from .writers import write_csv as write_csv
from .writers import write_format as write_format
from .writers import write_part as write_part
from .writers import write_ply as write_ply

"""The face of `prismcore.multiview`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .joint import JointResult as JointResult
from .joint import fit_views as fit_views
from .report import joint_report as joint_report
from .views import View as View

"""The face of `prismcore.quality`: its public names, each once, with the module that
defines it. `lazy_loader.attach_stub` reads this file at run time (each name imported on first
use) and type checkers read it as the package's interface."""

from .verdicts import DimensionVerdict as DimensionVerdict
from .verdicts import Verdict as Verdict
from .verdicts import judge as judge
from .verdicts import quality_block as quality_block
from .verdicts import quality_from_report as quality_from_report
from .verdicts import report_quality as report_quality

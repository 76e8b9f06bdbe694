"""The engine's version, written into every report (its own module: the stages import it without
importing the package's ``__init__``, which re-exports them)."""

__version__ = "0.1.0"

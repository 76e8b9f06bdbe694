"""The seeds of each set: the development set's and the report set's never overlap."""

from __future__ import annotations

from .layout import Settings

__all__ = ["handheld_seeds", "station_seeds"]

_BASE = {"development": 0, "report": 500_000}  # any other set (a test's) starts at 900_000


def station_seeds(settings: Settings, n: int) -> list[int]:
    """Seeds of `n` stations of the set `settings` names."""
    return [_BASE.get(settings.name, 900_000) + 100 + i for i in range(n)]


def handheld_seeds(settings: Settings, n: int) -> list[int]:
    """Seeds of `n` hand-held photos of the set `settings` names."""
    return [_BASE.get(settings.name, 900_000) + 50_000 + i for i in range(n)]

"""The commands' rich console, made when a command first prints.

rich costs ~40 ms of CPU to import; `prism --help` (plain click help) need not pay it.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["rich_console"]


@cache
def rich_console(*, soft_wrap: bool = False) -> Console:
    """One `rich.console.Console(soft_wrap=soft_wrap)` per process, made on first use."""
    from rich.console import Console
    return Console(soft_wrap=soft_wrap)

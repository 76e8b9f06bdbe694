"""Lazy public names for a package's ``__init__``: a name is imported from its module on first use.

Importing a subpackage then costs nothing until one of its names is read, so ``prismcore.spec``
(pydantic only) stays cheap for the API, and a command imports only the engine it runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_exports(
    package: str, exports: dict[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for `package`, whose public names live in submodules.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : dict of str to str
        Each public name mapped to the submodule (relative to `package`) that defines it.
    """

    def __getattr__(name: str) -> Any:  # noqa: N807 (the module hook PEP 562 names)
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{module}"), name)

    def __dir__() -> list[str]:  # noqa: N807 (the module hook PEP 562 names)
        return sorted(exports)

    return __getattr__, __dir__

"""The engine's import graph, read from the source with `ast` (every import: top-level, inside
functions, under ``TYPE_CHECKING``), for the layout test and the architecture page's diagram."""

from __future__ import annotations

import ast
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

SHARED = Path(__file__).resolve().parents[2] / "shared"
ENGINE = SHARED / "prismcore"


@dataclass(frozen=True)
class Import:
    source: str  # the importing module, dotted ("prismcore.scan.pipeline")
    target: str  # the imported module, dotted (a module of the engine when it is one)
    line: int


def module_name(path: Path, root: Path = SHARED) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def engine_modules() -> dict[str, Path]:
    """Every module of prismcore, by dotted name (a package by its ``__init__``)."""
    return {module_name(p): p for p in sorted(ENGINE.rglob("*.py"))}


def _resolve(name: str, modules: dict[str, Path]) -> str:
    """`name` as the module it loads: ``prismcore.scan.pipeline.run_scan`` -> the pipeline."""
    while name not in modules and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def imports_of(path: Path, modules: dict[str, Path]) -> list[Import]:
    """Every import in the file at `path`, each resolved to the module it loads."""
    source = module_name(path)
    is_package = path.stem == "__init__"
    found: list[Import] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [Import(source, a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolved against the importing module's package
                package = source if is_package else source.rsplit(".", 1)[0]
                for _ in range(node.level - 1):
                    package = package.rsplit(".", 1)[0]
                base = f"{package}.{base}" if base else package
            for alias in node.names:
                # `from a.b import c` loads a.b.c when c is a module, else a.b
                target = f"{base}.{alias.name}"
                if target not in modules:
                    target = base
                found.append(Import(source, target, node.lineno))
    return [
        Import(i.source, _resolve(i.target, modules), i.line)
        if i.target.split(".")[0] == "prismcore"
        else i
        for i in found
    ]


def engine_imports() -> list[Import]:
    """Every import of the engine, its packages' faces (``__init__.pyi``, which name the modules
    each public name is imported from on first use) included."""
    modules = engine_modules()
    faces = [p.with_suffix(".pyi") for p in modules.values() if p.with_suffix(".pyi").exists()]
    return [i for path in [*modules.values(), *faces] for i in imports_of(path, modules)]


def module_graph() -> dict[str, set[str]]:
    """Module -> the engine modules it imports (itself and its own parent packages left out:
    Python loads a module's packages before it anyway)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for i in engine_imports():
        internal = i.target.startswith("prismcore") and i.target != i.source
        if internal and not (i.source + ".").startswith(i.target + "."):
            graph[i.source].add(i.target)
    return graph


def unit(module: str) -> str:
    """The unit of the layering a module belongs to: its subpackage (``scan``), a top-level
    module of the contract (``spec``), or ``prismcore`` for the package's own ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def package_graph() -> dict[str, set[str]]:
    """Subpackage (or top-level module) -> the others it imports: the architecture's edges."""
    graph: dict[str, set[str]] = defaultdict(set)
    for source, targets in module_graph().items():
        for target in targets:
            if unit(source) != unit(target):
                graph[unit(source)].add(unit(target))
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan), each a circle of imports."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    nodes = set(graph) | {t for ts in graph.values() for t in ts}
    for node in sorted(nodes):
        if node not in index:
            visit(node)
    return found

"""The engine's layout: imports run one way down the layers, no circle, no module too long to
read, nothing of the services or the test renderer inside the engine (read from the source by
`import_graph`, function-local imports included), and the architecture page's diagram of the
packages (docs/explanation/architecture.md) drawing exactly the imports there are."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest
from import_graph import (
    ENGINE,
    SHARED,
    cycles,
    engine_imports,
    engine_modules,
    module_graph,
    module_name,
    package_graph,
    unit,
)

# Bottom to top: a unit may import only units of the layers below its own (not its siblings).
# The contract callers hand the engine comes first, then the stages in the order a scan uses them.
LAYERS: list[set[str]] = [
    {"_version", "errors", "formats"},
    {"bounds"},
    {"camera"},
    {"spec_fields"},
    {"spec"},
    {"report"},
    {"io", "quality"},
    {"geometry"},
    {"scan"},
    {"locate", "multiview"},
    {"video", "outputs", "station"},
    {"prismcore"},  # the package's __init__: re-exports what integrators use
]
LAYER = {name: i for i, layer in enumerate(LAYERS) for name in layer}

# What the engine never imports: the test renderers, the services, their frameworks.
FORBIDDEN = {
    "prismsynth", "prismpbr", "mitsuba", "prism_api", "prism_worker", "prism_cli", "prism_common", "services",
    "fastapi", "starlette", "uvicorn", "celery", "kombu", "redis", "boto3", "botocore",
}

MAX_LINES = 600


def test_every_unit_has_a_layer():
    units = {unit(m) for m in engine_modules()}
    assert units - set(LAYER) == set(), "add the new subpackage to LAYERS (and the architecture page)"


def test_no_import_circle():
    assert cycles(module_graph()) == []


def test_imports_run_down_the_layers():
    upward = [
        f"{i.source} (line {i.line}) imports {i.target}"
        for i in engine_imports()
        if i.target.startswith("prismcore")
        and unit(i.source) != unit(i.target)
        and i.source != "prismcore"
        and LAYER[unit(i.target)] >= LAYER[unit(i.source)]
    ]
    assert upward == []


def test_package_graph_is_layered():
    # the same rule at the level of the architecture page's diagram
    for source, targets in package_graph().items():
        for target in targets:
            assert LAYER[target] < LAYER[source], f"{source} -> {target}"


def test_engine_imports_nothing_of_the_services():
    bad = [
        f"{i.source} (line {i.line}) imports {i.target}"
        for i in engine_imports()
        if i.target.split(".")[0] in FORBIDDEN
    ]
    assert bad == []


@pytest.mark.parametrize("package", ["prismcore", "prismsynth"])
def test_no_module_too_long(package):
    lengths = {
        str(p.relative_to(SHARED)): len(p.read_text(encoding="utf-8").splitlines())
        for p in sorted((SHARED / package).rglob("*.py"))
    }
    too_long = {name: n for name, n in lengths.items() if n > MAX_LINES}
    assert too_long == {}, f"split by what the parts do (over {MAX_LINES} lines)"


def test_public_names_import():
    """Every name a package's __init__ exports is where it says."""
    for path in sorted(ENGINE.rglob("__init__.py")):
        name = ".".join(path.relative_to(SHARED).parent.parts)
        package = importlib.import_module(name)
        for public in getattr(package, "__all__", []):
            assert getattr(package, public) is not None, f"{name}.{public}"


ARCHITECTURE = SHARED.parent / "docs" / "explanation" / "architecture.md"
CONTRACT = {"errors", "bounds", "camera", "formats", "spec_fields", "spec", "report", "_version"}


def _drawn() -> tuple[dict[str, set[str]], list[str]]:
    """The architecture page's diagram: each subpackage's drawn imports, and the contract's order."""
    page = ARCHITECTURE.read_text(encoding="utf-8")
    section = page.split("## The engine's packages", 1)[1]
    diagram = section.split("```text\n", 1)[1].split("```", 1)[0]
    edges: dict[str, set[str]] = {}
    contract: list[str] = []
    for line in diagram.splitlines():
        if line.startswith("contract:"):
            contract = [m.strip() for m in line.removeprefix("contract:").split("->")]
            continue
        name, _, targets = line.partition("->")
        edges[name.strip()] = {t.strip() for t in targets.split(",") if t.strip()}
    return edges, contract


def test_the_architecture_page_draws_the_real_imports():
    drawn, contract = _drawn()
    subpackages = {unit(m) for m in engine_modules()} - CONTRACT - {"prismcore"}
    assert set(drawn) == subpackages, "every subpackage has its line in the diagram"
    real = {s: {t for t in ts if t in subpackages} for s, ts in package_graph().items() if s in subpackages}
    for name in subpackages:
        assert drawn[name] == real.get(name, set()), f"{name}: drawn {drawn[name]}, imports {real.get(name)}"
    # each arrow points down the picture
    order = list(drawn)
    for name, targets in drawn.items():
        assert all(order.index(t) > order.index(name) for t in targets), f"{name} imports one drawn above it"
    # the contract's modules each import only those drawn after them
    graph = package_graph()
    assert set(contract) == CONTRACT - {"_version"}
    for i, name in enumerate(contract):
        assert graph.get(name, set()) - {"_version"} <= set(contract[i + 1:]), name


# The engine's faces: each package's ``__init__`` (its names listed once, in ``__init__.pyi``) is
# its interface, and the contract's top-level modules are the engine's; a service reads only those.
SERVICES = SHARED.parent / "services"
SERVICE_PACKAGES = {"api": "prism_api", "worker": "prism_worker", "cli": "prism_cli",
                    "common": "prism_common"}


def _imported_names(path: Path, source: str) -> list[tuple[str, str, int]]:
    """(module, name, line) of every ``from module import name`` in the file, relative ones resolved."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                package = source if path.stem == "__init__" else source.rsplit(".", 1)[0]
                for _ in range(node.level - 1):
                    package = package.rsplit(".", 1)[0]
                base = f"{package}.{base}" if base else package
            found += [(base, alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.Import):
            found += [(alias.name, "", node.lineno) for alias in node.names]
    return found


def _service_files() -> dict[str, Path]:
    return {
        ".".join([SERVICE_PACKAGES[p.relative_to(SERVICES).parts[0]],
                  *p.relative_to(SERVICES).with_suffix("").parts[1:]]).removesuffix(".__init__"): p
        for p in sorted(SERVICES.rglob("*.py"))
        if p.relative_to(SERVICES).parts[0] in SERVICE_PACKAGES
    }


def _package(module: str) -> str:
    """A private name's owner: the engine's subpackage, the contract (its top-level modules, one
    unit of meaning), or the service's package."""
    if module.split(".")[0] != "prismcore":
        return module.split(".")[0]
    name = unit(module)
    return "contract" if name in CONTRACT else name


def test_no_private_name_crosses_a_package():
    files = {module_name(p): p for p in engine_modules().values()} | _service_files()
    crossing = [
        f"{source} (line {line}) imports {target}.{name}"
        for source, path in files.items()
        for target, name, line in _imported_names(path, source)
        if target.startswith("prismcore") and name.startswith("_") and not name.startswith("__")
        and _package(target) != _package(source)
    ]
    assert crossing == [], "make the name public (and put it in the package's face) or keep it home"


def test_services_import_only_the_engines_faces():
    subpackages = {unit(m) for m in engine_modules()} - CONTRACT - {"prismcore"}
    faces = {"prismcore"} | {f"prismcore.{name}" for name in subpackages | CONTRACT - {"_version"}}
    behind = [
        f"{source} (line {line}) imports {target}"
        for source, path in _service_files().items()
        for target, _, line in _imported_names(path, source)
        if target.split(".")[0] == "prismcore" and target not in faces
    ]
    assert behind == [], "import from the package's face (add the name to its __init__.pyi)"

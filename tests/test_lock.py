"""The installed packages are the locked ones, and the locks are those `scripts/lock` makes.

The engine's decisions (a face found or not, an edge fit kept or not) were seen to differ between
numpy/OpenCV releases, so a fresh clone must run exactly what CI ran: `scripts/setup` installs
`locks/test.txt` (and `locks/open3d.txt`; the Dockerfile `locks/service.txt`) with their hashes,
and these tests fail when the environment has drifted from them or pyproject.toml asks for
something they do not hold.
"""

from __future__ import annotations

import importlib.metadata
import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
LOCK = ROOT / "locks" / "test.txt"
SERVICE_LOCK = ROOT / "locks" / "service.txt"
OPEN3D_LOCK = ROOT / "locks" / "open3d.txt"
_PIN = re.compile(r"^([A-Za-z0-9_.\-\[\]]+)==([^\s;\\]+)\s*(?:;\s*([^\\]+?))?\s*\\?$")


def locked(path: Path) -> dict[str, Version]:
    """Name -> version of each pin in a lock whose marker holds on this interpreter."""
    pins: dict[str, Version] = {}
    for line in path.read_text().splitlines():
        m = _PIN.match(line)
        if m is None:
            continue
        name, version, marker = m.groups()
        if marker and not Marker(marker).evaluate():
            continue
        pins[canonicalize_name(name.split("[")[0])] = Version(version)
    return pins


def installed(name: str) -> Version | None:
    try:
        return Version(importlib.metadata.version(name))
    except importlib.metadata.PackageNotFoundError:
        return None


def _differences(pins: dict[str, Version]) -> dict[str, str]:
    return {name: f"locked {want}, installed {have}" for name, want in pins.items()
            if (have := installed(name)) != want}


def test_every_locked_package_is_installed_at_its_locked_version() -> None:
    pins = locked(LOCK)
    assert {"numpy", "opencv-python-headless", "scipy", "pillow", "kombu"} <= pins.keys()
    assert not _differences(pins), "the install differs from locks/test.txt; run scripts/setup"


@pytest.mark.parametrize("name", ["numpy", "opencv-python-headless", "scipy", "pillow"])
def test_the_numerics_have_one_pin_for_every_python(name: str) -> None:
    # Every machine runs one release of what the engine's decisions rest on, whatever its
    # Python 3.11+ (scripts/lock's --fork-strategy fewest).
    pins = [line for line in LOCK.read_text().splitlines() if line.startswith(f"{name}==")]
    assert len(pins) == 1 and ";" not in pins[0], pins


def test_what_is_installed_of_the_open3d_lock_is_the_locked_version() -> None:
    # Open3D is optional (scripts/setup goes on without it), so its lock is held to what is
    # there: whatever of it is installed is at its pin, and Open3D itself when present.
    pins = locked(OPEN3D_LOCK)
    assert "open3d-cpu" in pins
    present = {name: want for name, want in pins.items() if installed(name) is not None}
    assert not _differences(present)


def _requirements() -> list[Requirement]:
    """pyproject's requirements that apply on this interpreter (their markers hold)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    every = [Requirement(r) for r in
             project["dependencies"] + extras["test"] + extras["cad"] + extras["open3d"]]
    return [r for r in every if r.marker is None or r.marker.evaluate()]


@pytest.mark.parametrize("requirement", _requirements(), ids=str)
def test_the_locks_satisfy_pyproject(requirement: Requirement) -> None:
    # A dependency added or narrowed in pyproject.toml without `scripts/lock` fails here.
    pins = locked(LOCK) | locked(OPEN3D_LOCK)
    name = canonicalize_name(requirement.name)
    assert name in pins, f"{name} is not locked: run scripts/lock"
    assert requirement.specifier.contains(pins[name], prereleases=True), (
        f"{name}: locked {pins[name]} is outside {requirement.specifier}: run scripts/lock")


@pytest.mark.parametrize("other", [SERVICE_LOCK, OPEN3D_LOCK], ids=lambda p: p.name)
def test_the_locks_agree_on_what_they_share(other: Path) -> None:
    # The service image runs the versions the tests ran.
    main, extra = locked(LOCK), locked(other)
    assert {n: (main[n], extra[n]) for n in main.keys() & extra.keys() if main[n] != extra[n]} == {}


@pytest.mark.slow
def test_scripts_lock_rebuilds_the_committed_locks(tmp_path: Path) -> None:
    # The README's refresh command, run on a copy: with pins kept it must change nothing, so
    # the committed locks are what the command makes from pyproject.toml (needs PyPI).
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, tmp_path / name)
    shutil.copytree(ROOT / "locks", tmp_path / "locks")
    (tmp_path / "scripts").mkdir()
    shutil.copy(ROOT / "scripts" / "lock", tmp_path / "scripts" / "lock")
    run = subprocess.run(["scripts/lock"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    for lock in (ROOT / "locks").iterdir():
        fresh = (tmp_path / "locks" / lock.name).read_text()
        assert fresh == lock.read_text(), f"{lock.name} is stale: run scripts/lock"


@pytest.mark.slow
def test_the_dockerfiles_install_steps_make_a_working_service(tmp_path: Path) -> None:
    # No Docker engine runs here: the image's two pip steps run as written in a fresh venv, on
    # the files the Dockerfile copies, and the API's app must import from the result.
    steps = [line.removeprefix("RUN ").split("&&")[0].strip()
             for line in (ROOT / "Dockerfile").read_text().splitlines() if line.startswith("RUN pip ")]
    assert steps == ["pip install --require-hashes -r locks/service.txt", "pip install --no-deps ."]
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, tmp_path / name)
    for name in ("locks", "shared", "services"):
        shutil.copytree(ROOT / name, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__", "static"))
    venv = tmp_path / "venv"
    subprocess.run(["python3", "-m", "venv", str(venv)], check=True)
    for step in steps:
        run = subprocess.run([str(venv / "bin" / "python"), "-m", *step.split()], cwd=tmp_path,
                             capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, (step, run.stderr[-2000:])
    # every package, the engine's subpackages and what the worker imports only when an item
    # needs it (a station's scan) included: a subpackage missing from pyproject's list was not in
    # the wheel, and the image failed on its first station item
    modules = [*source_packages(), "prism_api.main", "prism_worker.app", "prism_worker.station_item",
               "prismcore.scan.pipeline", "prismcore.station.scan"]
    each = "import importlib, sys\nfor m in sys.argv[1:]: importlib.import_module(m)"
    check = subprocess.run([str(venv / "bin" / "python"), "-c", each, *modules],
                           cwd="/", capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stderr[-2000:]


def source_packages() -> list[str]:
    """Every package (a folder with an __init__.py) under pyproject's package-dir roots."""
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = set()
    for name, folder in setuptools["package-dir"].items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder)
            found.add(".".join([name, *rel.parts]))
    return sorted(found)


def test_the_wheel_lists_every_package() -> None:
    # `pip install --no-deps .` (the image) installs only the packages pyproject lists
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert sorted(setuptools["packages"]) == source_packages()

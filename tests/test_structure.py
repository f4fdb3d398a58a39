"""The architecture's rules (docs/architecture.md, docs/decisions/0002), checked on the source:
the import direction between the packages, and the one import name the installed package has."""

from __future__ import annotations

import ast
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("analysis", "drivers", "reports", "lab", "rig", "ui", "config", "hopkinson")
TOP_LEVEL_FOLDERS = ("analysis", "drivers", "reports", "lab", "rig", "ui")
STDLIB = set(sys.stdlib_module_names)
# The root package's own modules (the version, file safety): standard library only, usable by all.
ROOT_MODULES = {"hopkinson", "hopkinson.fileio"}

# Imports that break a rule today and are being moved (each entry names its file and module).
# The list only ever shrinks; an entry that no longer occurs fails the test too.
KNOWN_EXCEPTIONS: set[tuple[str, str]] = set()


def _sources(folder: str) -> Iterator[Path]:
    yield from sorted((REPO / folder).rglob("*.py"))


def _absolute_imports(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module


def _violation(rel: str, module: str) -> str | None:
    """Why importing `module` from the file `rel` breaks the layout, or None."""
    top = module.split(".")[0]
    if top in TOP_LEVEL_FOLDERS:
        return "imports a bare top-level name: the installed package is `hopkinson.…`"
    if top in STDLIB or top == "__future__" or module in ROOT_MODULES:
        return None
    folder = rel.split("/")[0]
    inside = module.startswith("hopkinson.")
    sub = module.split(".")[1] if inside and module.count(".") >= 1 else None
    if folder == "analysis":
        if top in ("numpy", "scipy") or sub == "analysis":
            return None
        return "analysis/ imports only NumPy, SciPy and itself"
    if folder == "drivers":
        if rel.startswith("drivers/sim/") and inside and module.startswith("hopkinson.analysis.bar"):
            return None  # the simulated world fires through the bar's physics (issue 19), pure NumPy/SciPy
        if rel.startswith("drivers/sim/") and inside and not module.startswith("hopkinson.drivers.sim"):
            return "drivers/sim/ (the simulated world) imports no driver"
        if inside and sub != "drivers":
            return "drivers/ imports nothing of rig/, analysis/, reports/ or ui/"
        return None
    if folder == "reports":
        if inside and sub not in ("analysis", "reports"):
            return "reports/ imports only analysis/ of the project"
        return None
    if folder == "lab":
        if inside and sub not in ("analysis", "reports", "lab"):
            return "lab/ imports only analysis/ and reports/ of the project (never rig/ or ui/)"
        return None
    if folder == "rig":
        if inside and sub == "ui" and not rel.startswith("rig/cli/"):
            return "rig/ never imports ui/ (only the `panel` command starts it)"
        if module.startswith("hopkinson.rig.cli") and not rel.startswith("rig/cli/"):
            return "only the command line imports the command line"
        return None
    if folder == "ui":
        if module.startswith("hopkinson.rig.cli"):
            return "ui/ never imports the command line"
        return None
    return None


def test_import_direction_between_packages() -> None:
    found: set[tuple[str, str]] = set()
    problems = []
    for folder in TOP_LEVEL_FOLDERS:
        for path in _sources(folder):
            rel = path.relative_to(REPO).as_posix()
            for module in _absolute_imports(path):
                why = _violation(rel, module)
                if why is None:
                    continue
                if (rel, module) in KNOWN_EXCEPTIONS:
                    found.add((rel, module))
                else:
                    problems.append(f"{rel}: import {module}: {why}")
    assert not problems, "\n".join(problems)
    assert found == KNOWN_EXCEPTIONS, f"no longer occurs, remove from KNOWN_EXCEPTIONS: {KNOWN_EXCEPTIONS - found}"


def test_tests_and_benchmarks_import_the_installed_name() -> None:
    problems = []
    for folder in ("tests", "benchmarks"):
        for path in _sources(folder):
            for module in _absolute_imports(path):
                if module.split(".")[0] in TOP_LEVEL_FOLDERS:
                    problems.append(f"{path.relative_to(REPO)}: import {module}")
    assert not problems, "\n".join(problems)


def test_every_package_folder_is_mapped_into_hopkinson() -> None:
    setuptools = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    mapping: dict[str, str] = setuptools["package-dir"]
    listed = set(setuptools["packages"])
    on_disk = set()
    for folder in PACKAGES:
        for init in (REPO / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(REPO).as_posix()
            top, _, rest = rel.partition("/")
            name = "hopkinson" if top == "hopkinson" else f"hopkinson.{top}"
            assert mapping[name] == top
            on_disk.add(name + ("." + rest.replace("/", ".") if rest else ""))
    assert listed == on_disk


def test_the_root_package_imports_only_the_standard_library() -> None:
    for path in _sources("hopkinson"):
        for module in _absolute_imports(path):
            top = module.split(".")[0]
            assert top in STDLIB or top == "__future__" or module in ROOT_MODULES or \
                path.name == "__main__.py", f"{path}: import {module}"


@pytest.mark.parametrize("folder", TOP_LEVEL_FOLDERS)
def test_no_module_uses_a_path_relative_to_the_source_tree_for_config(folder: str) -> None:
    # The shipped configurations are package data (hopkinson.rig.config_paths), so an installed
    # copy finds them; a path built from __file__ up to the repository would not exist there.
    for path in _sources(folder):
        text = path.read_text(encoding="utf-8")
        assert 'parent / "config"' not in text and "parents[1] / \"config\"" not in text, path


def test_reading_a_configuration_or_a_campaign_does_not_load_the_bar_model() -> None:
    """The bar model (NumPy + SciPy) is imported where a level or a plan is computed, not by
    every command that reads rig.toml or a campaign; the configuration's material and mount names are
    the bar model's own."""
    import subprocess
    import sys

    probe = ("import sys, hopkinson.rig.config, hopkinson.rig.campaign; "
             "print(sorted(m for m in ('scipy', 'hopkinson.analysis.bar') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.strip()
    assert loaded == "[]"
    from hopkinson.analysis.bar import MATERIALS
    from hopkinson.analysis.bar.geometry import MOUNTS
    from hopkinson.rig.config import BAR_MATERIALS, BAR_MOUNTS

    assert set(BAR_MATERIALS) == set(MATERIALS)
    assert BAR_MOUNTS == MOUNTS


def test_every_study_with_a_longer_hang_guard_still_defines_its_fixture() -> None:
    """tests/conftest.py's STUDY_FIXTURES names each study's module and fixture: a renamed module
    or fixture would silently give its tests back the 300 s guard the study outlasts."""
    from tests.conftest import STUDY_FIXTURES, TESTS

    for module, fixture in STUDY_FIXTURES.items():
        tree = ast.parse((TESTS / module).read_text(encoding="utf-8"))
        fixtures = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)
                    and any("fixture" in ast.unparse(d) for d in node.decorator_list)}
        assert fixture in fixtures, f"{module} defines no fixture {fixture!r} (tests/conftest.py STUDY_FIXTURES)"

"""Shared test set-up. QT_QPA_PLATFORM must be set before any Qt import."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")
# Threaded OpenBLAS on a small shared machine makes long dot products and SVDs 10-50x
# slower at random; the analysis is single-threaded by design.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

pytest_plugins = ("tests.scope_order",)  # longest modules first on the xdist workers

ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"

# The statistical studies in tests/analysis (module fixtures of 50-140 simulated shots: 40-65 s of
# CPU on an idle machine; marked `study`, so `make studies` and CI's oldest-pair stage run them, not
# `make test`) are charged to the first test that asks for them. On a machine half as
# fast with other work beside it (seen: a coverage study in another checkout) that test outlasted
# pyproject.toml's 300 s hang guard, whose thread method ends the xdist worker ("node down: Not
# properly terminated"). The tests that use one get a longer guard; every other test keeps 300 s.
# Keyed by the module's path under tests/ (a study of the same file name elsewhere, e.g. in
# tests/studies, keeps the timeout `make studies` gives it); tests/test_structure.py checks that
# each module still defines its fixture, so a rename cannot drop the guard unnoticed.
STUDY_FIXTURES = {"analysis/test_coverage_realistic.py": "study", "analysis/test_uncertainty.py": "shots",
                  "analysis/test_linearity.py": "campaigns"}
TESTS = Path(__file__).resolve().parent
STUDY_TIMEOUT_S = 1500


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A longer hang guard for the tests that use a study's fixture (STUDY_FIXTURES)."""
    for item in items:
        fixture = STUDY_FIXTURES.get(item.path.relative_to(TESTS).as_posix()) if item.path.is_relative_to(TESTS) else None
        if fixture is not None and fixture in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.timeout(STUDY_TIMEOUT_S))


@pytest.fixture(autouse=True)
def private_rig_folders(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test keeps rig locks (rig/lock.py) and the simulator's runtime files (pty links,
    addresses, state) in folders of its own: never the machine's shared ones, and no clash
    between tests running in parallel. The lab's record (hopkinson.lab) likewise: a data folder
    of its own, never the user's database."""
    monkeypatch.setenv("HOPKINSON_LOCK_DIR", str(tmp_path_factory.mktemp("locks")))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path_factory.mktemp("data")))
    monkeypatch.delenv("HOPKINSON_DATABASE_URL", raising=False)
    runtime = tmp_path_factory.mktemp("runtime")
    runtime.chmod(0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    """A folder (git-ignored) where tests save screenshots and plots for people to look at."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS


def pytest_collection_finish(session: pytest.Session) -> None:
    """Freeze the objects the imports and the collection made (gc.freeze, after one collection so
    that no garbage is frozen): every later full collection skips them. A worker imports NumPy,
    SciPy, matplotlib, PySide6, pyqtgraph, SQLAlchemy and the product (~250 000 objects; 0.12 s
    per full collection on this session's 2-core machine, more on a slower one), and walked them
    again at every automatic generation-2 collection and at ui.app.dispose's gc.collect after each
    panel a test closes. Measured 2026-11-29 (`make test`, 3 workers): user CPU 294, 305 and
    315 s against 327 and 320 s without, wall 3:21, 3:29 and 3:33 against 3:37 and 3:33 (a few
    per cent; runs differ by ±10 s). What is frozen
    lives for the whole run anyway (modules, classes, functions, the collected tests); one of them
    that became garbage later would only stay unfreed. Objects the tests make are not frozen."""
    import gc

    gc.collect()
    gc.freeze()

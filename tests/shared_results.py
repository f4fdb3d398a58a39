"""A result computed once per test run and shared by the xdist workers (`make test`: -n 3).

A module-level cache (functools.cache) or a session fixture lives in one worker process; two
modules that need the same expensive result compute it twice when loadscope puts them on
different workers. Here the first worker to ask computes it, under a file lock, and writes it
(pickled) into the run's own temporary folder (the parent of the workers' base folders, fresh
for every run and removed by pytest with old runs); the others wait on the lock and read it.
Nothing outlives the run, so no result is ever stale.
"""

from __future__ import annotations

import fcntl
import os
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

T = TypeVar("T")


def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder this run's workers share (the base folder itself without xdist)."""
    base = tmp_path_factory.getbasetemp()
    shared = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "shared-results"
    shared.mkdir(exist_ok=True)
    return shared


def once_per_run(folder: Path, key: str, compute: Callable[[], T]) -> T:
    """`compute()`'s result for `key` (a file name part), computed by the first process of the
    run that asks and read back by the others."""
    path = folder / f"{key}.pickle"
    with open(folder / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, also if compute() raises
        if path.exists():
            return pickle.loads(path.read_bytes())
        result = compute()
        partial = path.with_suffix(".tmp")
        partial.write_bytes(pickle.dumps(result))
        partial.replace(path)
        return result

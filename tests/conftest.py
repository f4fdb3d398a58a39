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

ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    """A folder (git-ignored) where tests save screenshots and plots for people to look at."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS

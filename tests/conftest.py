"""Shared test set-up. QT_QPA_PLATFORM must be set before any Qt import."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    """A folder (git-ignored) where tests save screenshots and plots for people to look at."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS

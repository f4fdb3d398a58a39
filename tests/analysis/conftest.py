"""Fixtures shared by the analysis tests."""

from tests.analysis.ptb_fixtures import analyses  # noqa: F401  (session-wide)

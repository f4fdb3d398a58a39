"""Analyses of PTB's record, its variants, its hybrids and simulated shots, shared by the test
session: a record is identified once (the identification is deterministic) and its Monte Carlo
uncertainty evaluated once per (draws, seed), so a test over several seeds re-runs only the
draws. The uncertainty is the shot analysis's own (`shot_analysis.with_uncertainty`, what
`analyse_record` calls after identifying), so the intervals and warnings are those `analyse_record`
gives with the same draws and seed; the DCM, which these tests do not read, is not designed.

Seeds here are fixed before any result is seen (`seeds(first, count)`), never picked to pass:
each test states how many may miss and what that threshold's pass probability is.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

import pytest

from hopkinson.analysis.identify import Identification, identify
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.records import Record
from hopkinson.analysis.shot_analysis import with_uncertainty


@dataclass
class Analysed:
    """One record's identification with the uncertainty of one (draws, seed): the parts of
    analysis.shot_analysis.ShotAnalysis these tests read, under the same names."""

    identification: Identification
    uncertainty: dict[str, Any]
    warnings: list[str] = field(default_factory=list)

    @property
    def model(self) -> DiscreteModel:
        return self.identification.model


class Analyses:
    """The session's cache: identifications by key, uncertainties by (key, draws, seed)."""

    def __init__(self) -> None:
        self._identified: dict[Hashable, Identification] = {}
        self._analysed: dict[tuple[Hashable, int, int], Analysed] = {}

    def identification(self, key: Hashable, record: Callable[[], Record]) -> Identification:
        """The default identification of `record()` (built only on the first call for `key`)."""
        if key not in self._identified:
            self._identified[key] = identify(record())
        return self._identified[key]

    def analysed(self, key: Hashable, record: Callable[[], Record], seed: int, draws: int) -> Analysed:
        """`record()` identified and its uncertainty drawn with `draws` and `seed`, as
        `analyse_record(record(), AnalysisOptions(draws=draws, seed=seed))` gives them."""
        if (key, draws, seed) not in self._analysed:
            fitted = with_uncertainty(self.identification(key, record), AnalysisOptions(draws=draws, seed=seed))
            assert fitted.uncertainty is not None, (key, seed, fitted.warnings)
            self._analysed[(key, draws, seed)] = Analysed(fitted.identification, fitted.uncertainty, fitted.warnings)
        return self._analysed[(key, draws, seed)]


@pytest.fixture(scope="session")
def analyses() -> Analyses:
    return Analyses()


def seeds(first: int, count: int) -> list[int]:
    """`count` consecutive Monte Carlo seeds from `first`."""
    return list(range(first, first + count))

"""The report tests' shots, analysed once per test run and shared by the xdist workers
(tests/shared_results.py): each report module may run on another worker."""

from __future__ import annotations

import pytest

from hopkinson.analysis.shot_analysis import ShotAnalysis
from tests.reports.simulated_shots import analysed_shots
from tests.shared_results import once_per_run, run_folder


@pytest.fixture(scope="module")
def analyses(tmp_path_factory: pytest.TempPathFactory) -> dict[str, ShotAnalysis]:
    """`analysed_shots()`: "a1", "a2" (SENSOR_A) and "b1" (SENSOR_B)."""
    return once_per_run(run_folder(tmp_path_factory), "report-analysed-shots", analysed_shots)

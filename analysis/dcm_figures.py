"""What a DCM buys on its model: the compensated FBSD, the step responses, rise and settling times."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.response import (
    DEFAULT_LEVELS,
    BandEdge,
    band_edges,
    frequency_response,
    model_output,
    pole_zero_frequencies_hz,
    response_times_samples,
)

if TYPE_CHECKING:
    from hopkinson.analysis.dcm import DCM

MAX_SIMULATED_SAMPLES = 4_000_000  # longest step or impulse response simulated


def _same_interval(model: DiscreteModel, dcm: DCM) -> None:
    if abs(model.sample_interval_s - dcm.sample_interval_s) > 1e-9 * model.sample_interval_s:
        raise AnalysisError(
            f"the DCM was designed for a sample interval of {dcm.sample_interval_s:g} s, the model has "
            f"{model.sample_interval_s:g} s"
        )


def compensated_fbsd_edges(
    model: DiscreteModel, dcm: DCM, levels: Sequence[float] = DEFAULT_LEVELS
) -> dict[str, BandEdge]:
    """Band edges of the model followed by the DCM, searched up to Nyquist."""
    _same_interval(model, dcm)
    dc = abs(model.dc_gain * dcm.dc_gain)
    if dc == 0:
        raise AnalysisError("compensated FBSD: the model has zero DC gain")

    def gain(f: np.ndarray) -> np.ndarray:
        return np.abs(frequency_response(model, f) * dcm.frequency_response(f)) / dc

    special = pole_zero_frequencies_hz(np.concatenate([model.zeros, dcm.poles]), model.sample_interval_s)
    return band_edges(gain, 0.5 / model.sample_interval_s, levels, special)


def compensated_fbsd_hz(model: DiscreteModel, dcm: DCM, levels: Sequence[float] = DEFAULT_LEVELS) -> dict[str, float]:
    """FBSD in Hz of the compensated system (Nyquist where the band is never left)."""
    return {k: e.frequency_hz for k, e in compensated_fbsd_edges(model, dcm, levels).items()}


def _rise_time(step: np.ndarray) -> float:
    """10–90 % rise time in samples of a step response from rest normalised to 1, first
    crossings interpolated linearly (from the rest value 0 before the first sample, as from the
    zeros a FIR stage's delay puts before its response: the time does not depend on it)."""

    def first_crossing(level: float) -> float:
        idx = np.flatnonzero(step >= level)
        if idx.size == 0:
            raise AnalysisError("rise time: the step response never reaches 90 % of its final value")
        i = int(idx[0])
        before = float(step[i - 1]) if i > 0 else 0.0
        return (i - 1) + (level - before) / (step[i] - before)

    return first_crossing(0.9) - first_crossing(0.1)


def _settling_time(step: np.ndarray, tolerance: float) -> float:
    """Samples until the normalised step response stays within 1 ± tolerance."""
    outside = np.flatnonzero(np.abs(step - 1.0) > tolerance)
    return 0.0 if outside.size == 0 else float(outside[-1] + 1)


def step_responses(model: DiscreteModel, dcm: DCM, n_samples: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit-step responses normalised to their final values: (model alone, model then DCM), as
    a plot shows them. The model's sections are delay-free (its input delay only shifts the
    curve). The DCM's linear-phase FIR stage (its band limit) is a pure delay of half its
    length, removed here as alignment removes it from a record (its pre-ringing before the
    step's centre is then cut off). `n_samples` None: long enough for the slowest pole to
    settle (4 response times)."""
    alone, both, lead = _simulate_steps(model, dcm, n_samples)
    return alone[: alone.size - lead], both[lead:]


def _simulate_steps(model: DiscreteModel, dcm: DCM, n_samples: int | None) -> tuple[np.ndarray, np.ndarray, int]:
    """(alone, both, lead): the normalised step responses over n + lead samples from the step,
    lead the DCM's FIR stage's delay (0 without one)."""
    _same_interval(model, dcm)
    slowest = float(np.max(response_times_samples(np.concatenate([model.poles, dcm.poles]))))
    n = int(np.ceil(4 * slowest)) + model.b.size + dcm.order + 64 if n_samples is None else int(n_samples)
    lead = 0 if dcm.fir is None else (dcm.fir.size - 1) // 2
    if n + lead > MAX_SIMULATED_SAMPLES:
        raise AnalysisError(
            f"step response: a pole settles in {slowest:.3g} samples; too slow to simulate a step response"
        )
    final = model.dc_gain
    if final == 0:
        raise AnalysisError("step response: the model has zero DC gain")
    alone = model_output(model, np.ones(n + lead))
    return alone / final, dcm.filter(alone) / (final * dcm.dc_gain), lead


@dataclass(frozen=True)
class StepComparison:
    """The normalised step responses of the model alone and followed by the DCM (one simulation,
    `compare_steps`) and the times read off them, in samples: (without, with the DCM). `lead`:
    the DCM's FIR stage's pure delay, which the settling time leaves out (`step_responses`)."""

    alone: np.ndarray
    both: np.ndarray
    lead: int = 0

    def rise_times_samples(self) -> tuple[float, float]:
        """10–90 % rise times (of the whole responses: a linear-phase stage's step rises about
        its centre, half of it before the delay that alignment removes)."""
        return _rise_time(self.alone), _rise_time(self.both)

    def rise_time_ratio(self) -> float:
        """Uncompensated ÷ compensated 10–90 % rise time (> 1 when the DCM speeds it up). Both are
        above 0: interpolated from the rest before the step, a step complete at its first sample
        rises in 0.8 sample."""
        before, after = self.rise_times_samples()
        return before / after

    def settling_times_samples(self, tolerance: float = 0.05) -> tuple[float, float]:
        """Samples to settle within ±5 % of the final value (the compensated one counted from
        the step less the FIR stage's delay)."""
        return _settling_time(self.alone, tolerance), _settling_time(self.both[self.lead:], tolerance)

    def settling_time_ratio(self, tolerance: float = 0.05) -> float:
        """Uncompensated ÷ compensated time to settle within ±5 % (the paper's response time T_r):
        for a lightly damped sensor, the figure that shows what the DCM buys."""
        before, after = self.settling_times_samples(tolerance)
        return before / max(after, 1.0)


def compare_steps(model: DiscreteModel, dcm: DCM) -> StepComparison:
    """Simulate both step responses once for every time and ratio read off them."""
    return StepComparison(*_simulate_steps(model, dcm, None))


def rise_times_samples(model: DiscreteModel, dcm: DCM) -> tuple[float, float]:
    """10–90 % step-response rise times (samples): (model alone, model followed by the DCM)."""
    return compare_steps(model, dcm).rise_times_samples()


def rise_time_ratio(model: DiscreteModel, dcm: DCM) -> float:
    """Uncompensated ÷ compensated 10–90 % rise time (> 1 when the DCM speeds it up)."""
    return compare_steps(model, dcm).rise_time_ratio()


def settling_times_samples(model: DiscreteModel, dcm: DCM, tolerance: float = 0.05) -> tuple[float, float]:
    """Samples to settle within ±5 % of the final value: (model alone, model followed by the DCM)."""
    return compare_steps(model, dcm).settling_times_samples(tolerance)


def settling_time_ratio(model: DiscreteModel, dcm: DCM, tolerance: float = 0.05) -> float:
    """Uncompensated ÷ compensated time to settle within ±5 % (see StepComparison.settling_time_ratio)."""
    return compare_steps(model, dcm).settling_time_ratio(tolerance)


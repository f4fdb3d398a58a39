"""Group delays of a pole-zero system or a model, in samples: exact at DC, or the passband's."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel


def dc_group_delay_samples(zeros: np.ndarray, poles: np.ndarray) -> float:
    """Group delay at DC (samples) of k·Π(z − zeros)/Π(z − poles): see DCM.group_delay_samples."""
    z = np.atleast_1d(np.asarray(zeros, dtype=complex))
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    if np.any(np.abs(1 - z) < 1e-12) or np.any(np.abs(1 - p) < 1e-12):
        raise AnalysisError("group delay: a zero or pole at z = 1 has no delay at DC")
    return float(np.sum(np.real(1 / (1 - p))) - np.sum(np.real(1 / (1 - z))))


def passband_delay_samples(
    frequency_response: Callable[[np.ndarray], np.ndarray], band_hz: float, sample_interval_s: float
) -> float:
    """The delay (samples) that best lines up what a system passes in [0, band_hz]: the
    least-squares slope through the origin of its unwrapped phase against ω·T (256 points); why
    not the group delay at DC: docs/decisions/0020."""
    if not band_hz > 0:
        raise AnalysisError(f"passband delay: the band must be above 0 Hz, got {band_hz:g}")
    f = np.linspace(0.0, band_hz, 256)
    h = np.asarray(frequency_response(f), dtype=complex)
    if not np.all(np.isfinite(h)) or h[0] == 0:
        raise AnalysisError("passband delay: the response is not finite and non-zero at DC")
    phase = np.unwrap(np.angle(h / h[0]))
    w = 2 * np.pi * f * sample_interval_s
    return float(-np.dot(w, phase) / np.dot(w, w))


def model_dc_group_delay_samples(model: DiscreteModel) -> float:
    """Group delay at DC (samples) of the model B(z⁻¹)/A(z⁻¹), without its input delay: the
    phase slope of Σ b_k e^{−jωk} at ω = 0 is −Σ k·b_k/Σ b_k, so τ(0) = Σ k·b_k/Σ b_k − Σ k·a_k/Σ a_k
    (exact; no roots needed, a leading zero of b counts as its sample of delay)."""
    b, a = np.asarray(model.b, dtype=float), np.asarray(model.a, dtype=float)
    if np.sum(b) == 0 or np.sum(a) == 0:
        raise AnalysisError("group delay: the model has no finite, non-zero DC gain")
    return float(np.dot(np.arange(b.size), b) / np.sum(b) - np.dot(np.arange(a.size), a) / np.sum(a))

"""The claim stage of analysis.identify_stages: what the identified model may be said to show.

Modes outside the band the excitation supports are flagged `supported: False` (a DCM may only
cancel supported poles; the main mode is the lowest supported complex pair); a pair nearly
cancelled by a zero is a doublet, never a mode; the all-pole structure's resonance beyond the
band is marked `shapes_band` (its rise inside the band is measured, its place and damping are
not). A response leading the reference is reported, and a model whose delay was fitted negative
says so.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from hopkinson.analysis.findings import Finding, FindingCode
from hopkinson.analysis.frequency_fit import OrderFit, OrderProblem
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.modes import (
    RESONANCE_MAX_DAMPING,
    Mode,
    ModeKind,
    main_mode,
    mark_doublets,
    modes_of,
)
from hopkinson.analysis.numerics import f_quantile
from hopkinson.analysis.order_fit import ZETA_FLOOR
from hopkinson.analysis.spectral_data import SpectralData
from hopkinson.analysis.structure import DelayMode, Structure

# A response leading the reference by more than this (samples, significant) is reported.
LEAD_WARNING_SAMPLES = 0.2


def claimed_modes(model: DiscreteModel, band: tuple[float, float], structure: Structure) -> list[Mode]:
    """The model's modes (modes.modes_of) with their claims: supported inside `band`, doublets
    cancelled (modes.mark_doublets) and, in the all-pole structure, the resonance beyond the
    band marked `shapes_band`: it is what shapes the response inside the band (its rise), an
    effect that is measured though the pole's place and damping are not, so a DCM may cancel it
    (analysis.dcm_design; its band limit keeps it from amplifying beyond)."""
    modes = mark_doublets(modes_of(model.poles, model.sample_interval_s, band), model.zeros)
    if structure == Structure.ALL_POLE:
        modes = [replace(m, shapes_band=True) if m.kind == ModeKind.COMPLEX and not m.supported else m for m in modes]
    return modes


def delay_findings(data: SpectralData, fit: OrderFit, structure: Structure, dt: float, significance: float,
                   realigned_samples: int = 0) -> list[Finding]:
    """The response realigned before the fit (record_preparation.realigned: the lead the model
    then carries, from its delay and low-frequency group delay), the all-pole structure's delay
    fitted negative (a lead), or the free structure's causal model absorbing a lead into its
    zeros (lead_warning). `fit` is on the realigned record."""
    if realigned_samples:
        lead = _low_frequency_lead(replace(fit, delay=fit.delay - realigned_samples))
        return [Finding(FindingCode.REALIGNED,
                        f"the response leads the reference by about {lead:.3g} samples ({lead * dt * 1e6:.3g} µs): no "
                "sensor answers before it is excited, so this is the channels' skew (digitizer deskew, trigger "
                "alignment, cable lengths) or the reference chain's own delay (an interferometer's demodulation); "
                f"the response was realigned by {realigned_samples} samples before the fit, and the model's delay "
                "carries the lead (negative)")]
    if structure != Structure.ALL_POLE:
        return lead_findings(data, fit, dt, significance)
    if fit.delay < -LEAD_WARNING_SAMPLES:
        return [Finding(FindingCode.NEGATIVE_DELAY,
                        f"the response leads the reference by {-fit.delay:.2g} samples ({-fit.delay * dt * 1e6:.3g} "
                        "µs), fitted as a negative delay: the reference chain's own delay (an interferometer's "
                        "demodulation and low-pass) or the channels' skew (digitizer deskew, cable lengths)")]
    return []


def claim_findings(modes: list[Mode], band: tuple[float, float]) -> list[Finding]:
    """What each mode's claim (or its absence) means for the reader: doublets, resonances beyond
    the band placed by the rise they give inside it, modes outside the band, and no mode inside it."""
    out = []
    lo, hi = band
    for m in modes:
        f = m.natural_frequency_hz
        if m.cancelled:
            out.append(Finding(
                FindingCode.DOUBLET,
                f"the pole pair at {f / 1e3:.4g} kHz (ζ = {m.damping_ratio:.3g}) is nearly cancelled by a zero (a "
                "pole–zero doublet: the fit following a ripple of the data, not a resonance): it is not reported as "
                "a mode"
            ))
        elif m.shapes_band and f is not None:
            out.append(Finding(
                FindingCode.SHAPES_BAND,
                f"the resonance near {f / 1e3:.4g} kHz lies beyond the band the excitation supports ({lo / 1e3:.3g}–"
                f"{hi / 1e3:.3g} kHz): the all-pole model places it by the rise it gives inside the band, not by its "
                f"own peak; its frequency is an extrapolation and its damping is not determined (held ≥ "
                f"{ZETA_FLOOR:g}), so neither is reported as measured; the DCM cancels it for that rise"
            ))
        elif m.kind == ModeKind.COMPLEX and m.supported and m.resonance is False and f is not None:
            out.append(Finding(
                FindingCode.NO_RESONANCE,
                f"the pole pair at {f / 1e3:.4g} kHz is damped ζ = {m.damping_ratio:.3g} (more than "
                f"{RESONANCE_MAX_DAMPING:g}): it shapes the response but is no resonance, and is not reported as a mode"
            ))
        elif m.kind == ModeKind.COMPLEX and not m.supported and f is not None:
            out.append(Finding(
                FindingCode.MODE_OUTSIDE_BAND,
                f"the mode at {f / 1e3:.4g} kHz (ζ = {m.damping_ratio:.3g}) lies outside the band the excitation "
                f"supports ({lo / 1e3:.3g}–{hi / 1e3:.3g} kHz): this record cannot determine it, so it is kept out "
                "of the key figures and the DCM"
            ))
    if main_mode(modes) is None:
        beyond = [m for m in modes if m.kind == ModeKind.COMPLEX and not m.cancelled
                  and (m.natural_frequency_hz or 0.0) > hi]
        bound = (f"the resonance lies above {hi / 1e3:.3g} kHz, in a null of the excitation" if beyond
                 else "the sensor's natural frequency and damping are not reported")
        out.append(Finding(
            FindingCode.NO_MODE_IN_BAND,
            f"no resonance (complex pole pair) lies inside the supported band ({lo / 1e3:.3g}–{hi / 1e3:.3g} kHz): "
            f"{bound}; a shorter pulse would excite it"
        ))
    return out


def lead_findings(data: SpectralData, fit: OrderFit, dt: float, significance: float) -> list[Finding]:
    """Whether the response leads the reference. Two looks: the same order with the delay free
    to go negative fits significantly better (the causal model cannot follow the lead); or the
    causal model's whole group delay at low frequencies (delay + B's − A's) is negative. The
    second catches what the first misses: the delay and the zeros share a flat valley of the
    cost, so B's zeros take up the lead (a phase advance) as well as the free delay would,
    and the fitted delay alone says nothing. A sensor (modes above the band) lags at low
    frequencies by Σ 2ζ/ω_n: a whole lead is the channels' skew. (A lead smaller than the
    sensor's own lag cannot be told from it.)"""
    lead = _low_frequency_lead(fit)
    if fit.delay <= LEAD_WARNING_SAMPLES:
        problem = OrderProblem.for_fit(data, fit, DelayMode.FREE)
        free = problem.solve(replace(fit, cost=math.nan), 60)
        gain = fit.cost - free.cost
        dof = 2 * data.bins - problem.size
        if free.delay < -LEAD_WARNING_SAMPLES and dof > 0 and gain > 0:
            critical = f_quantile(1.0 - significance, 1, dof)
            if (2.0 * gain) / (2.0 * free.cost / dof) > critical:
                lead = max(lead, -free.delay)
    if lead <= LEAD_WARNING_SAMPLES:
        return []
    return [Finding(
        FindingCode.RESPONSE_LEADS,
        f"the response leads the reference by about {lead:.2g} samples ({lead * dt * 1e6:.3g} µs): no sensor answers "
        "before it is excited, so the channels are skewed (digitizer deskew, cable lengths, trigger alignment); the "
        "model is kept causal (delay ≥ 0) and absorbs the lead into its zeros, which biases it — correct the skew"
    )]


def _low_frequency_lead(fit: OrderFit) -> float:
    """The causal model's lead at low frequencies, samples (0 when it lags): minus its group
    delay at DC, τ + Σk·b_k/Σb_k − Σk·a_k/Σa_k. 0 when B or A nearly vanishes at DC (a
    differentiating model: no DC group delay to judge by)."""
    def group_delay(p: np.ndarray) -> float | None:
        total = float(np.sum(p))
        if abs(total) <= 1e-6 * float(np.sum(np.abs(p))):
            return None
        return float(np.dot(np.arange(p.size), p)) / total
    gd_b, gd_a = group_delay(np.asarray(fit.b, dtype=float)), group_delay(np.asarray(fit.a, dtype=float))
    if gd_b is None or gd_a is None:
        return 0.0
    return max(0.0, -(fit.delay + gd_b - gd_a))

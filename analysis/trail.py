"""How an identification was decided, told by its stages: what `hopkinson identify --explain`
prints.

`stage_trail` reads the stage results (analysis.record_preparation, analysis.identify_stages)
when the identification is assembled, one function per stage's account. The JSON report
carries the same figures (`noise`, `order_evidence`, `modes`), not the text.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from hopkinson.analysis.identify_stages import Claim, Settlement
from hopkinson.analysis.model_error import ModelError
from hopkinson.analysis.modes import RESONANCE_MAX_DAMPING, Mode, ModeKind, claimed
from hopkinson.analysis.noise import NoiseSpectrum
from hopkinson.analysis.order_choice import FRF_TOLERANCE
from hopkinson.analysis.record_preparation import PreparedRecord
from hopkinson.analysis.structure import Structure

HEADING = "how this identification was decided:"


class Stage(StrEnum):
    """The identification's stages, in the order they run."""

    PREPARE = "prepare"
    SEARCH_ORDERS = "search_orders"
    WEIGH_MODEL_ERROR = "weigh_model_error"
    SETTLE = "settle"
    CLAIM = "claim"


@dataclass(frozen=True)
class Step:
    """One line of the trail and the stage that decided it."""

    stage: Stage
    text: str


@dataclass(frozen=True)
class Trail:
    """What decided an identification, stage by stage."""

    steps: tuple[Step, ...]

    def of(self, stage: Stage) -> list[str]:
        """The lines of one stage."""
        return [s.text for s in self.steps if s.stage == stage]

    def text(self) -> str:
        """The trail as `--explain` prints it: a heading and one indented line per step."""
        return "\n".join([HEADING, *(f"  {s.text}" for s in self.steps)])


@dataclass(frozen=True)
class Stretch:
    """A stretch after the pulse the noise stage judged (times in s on the record's clock):
    coherent motion, or left out for `reason`."""

    start_s: float
    stop_s: float
    coherence: float | None  # power-weighted coherence of the channels (None: too short to judge)
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {"start_s": self.start_s, "stop_s": self.stop_s, "coherence": self.coherence, "reason": self.reason}


@dataclass(frozen=True)
class NoiseLevels:
    """Each channel's noise RMS (channel units; None: not measured) and where it was measured."""

    reference_rms: float | None
    response_rms: float | None
    reference_source: str
    response_source: str

    @classmethod
    def of(cls, prepared: PreparedRecord, noise_y: NoiseSpectrum) -> NoiseLevels:
        """The reference's as prepared, the response's measured on the residual (`noise_y`)."""
        noise = prepared.prep.noise
        return cls(noise.draw_noise_u.rms * prepared.scale_u if noise.draw_noise_u.samples else None,
                   noise_y.rms * prepared.scale_y if noise_y.samples else None, noise.draw_noise_u.source,
                   noise_y.source + (" less the model's response" if noise_y is not noise.draw_noise_y else ""))

    def to_dict(self) -> dict[str, Any]:
        return {"reference_rms": self.reference_rms, "response_rms": self.response_rms,
                "reference_source": self.reference_source, "response_source": self.response_source}


def stretches_after_pulse(prepared: PreparedRecord) -> list[Stretch]:
    """The stretches after the pulse the noise stage judged, on the record's clock."""
    rec, dt = prepared.record, prepared.record.sample_interval_s
    return [Stretch(rec.start_time_s + m["start_sample"] * dt, rec.start_time_s + m["stop_sample"] * dt,
                    m["coherence"], m["reason"]) for m in prepared.prep.noise.motion]


def order_criterion(significance: float) -> str:
    """The order test's rule in words (`significance`: the F test's level before correction)."""
    return ("the smallest order no higher order beats, both beyond chance (F test on the errors-in-variables cost V "
            f"at {significance:.0%}, Bonferroni-corrected over the fitted bins) and in the excitation-weighted "
            f"frequency response (by more than {FRF_TOLERANCE:.1%} RMS)")


# ------------------------------------------------------------------------------ each stage's account
def prepare_lines(prepared: PreparedRecord, levels: NoiseLevels, model_delay_samples: float) -> list[str]:
    """The noise and where it was measured, motion left out of it, a realignment, the band."""
    prep, rec, dt = prepared.prep, prepared.record, prepared.record.sample_interval_s

    def rms(v: float | None) -> str:
        return "not measured" if v is None else f"{v:.4g}"

    lines = [f"noise (RMS, channel units): reference {rms(levels.reference_rms)} ({levels.reference_source}), "
             f"response {rms(levels.response_rms)} ({levels.response_source})"]
    if prep.activity.lead_in:
        stop_s = rec.start_time_s + prep.activity.lead_in * dt
        to = ("to a quarter of the pulse's width before its foot: the window's margins left none"
              if prep.activity.lead_in_to_foot else "to the window's margin before the pulse")
        lines.append(f"lead-in at rest: {rec.start_time_s * 1e3:.4g}–{stop_s * 1e3:.4g} ms ({to})")
    else:
        lines.append("lead-in at rest: none (the pulse starts too near the record's start)")
    # without a lead-in at rest the noise is measured on the motion all the same (with a finding)
    lines += motion_lines(stretches_after_pulse(prepared), kept=not prep.activity.lead_in)
    alignment = prepared.alignment
    if alignment.shift:
        lines.append(f"realigned: the response delayed by {alignment.shift} samples before the fit (it led the "
                     f"reference by {alignment.lead:.3g} samples by their cross-correlation); the model's delay, "
                     f"{model_delay_samples:.3g} samples, carries the lead")
    if prep.band:
        lo, hi = prep.band
        lines.append(f"band: {lo / 1e3:.4g}–{hi / 1e3:.4g} kHz, where the reference's spectrum stands 20 dB above its "
                     f"noise and within 40 dB of its maximum; {prep.spectral.bins} bins fitted over {prep.u.size} "
                     "samples" + (" (a transient term fitted: the record ends before the response settles)"
                                  if prep.spectral.transient else ""))
    return lines


def motion_lines(stretches: Iterable[Stretch], kept: bool) -> list[str]:
    """Why each stretch after the pulse was left out of the noise (`kept`: measured as noise all
    the same, there being no lead-in at rest)."""
    lines = []
    for m in stretches:
        why = (f"moves coherently in both channels (power-weighted coherence {m.coherence:.2f})"
               if m.coherence is not None else m.reason or "too short to judge by coherence")
        lines.append(f"motion{'' if kept else ', not noise'}: {m.start_s * 1e3:.4g}–{m.stop_s * 1e3:.4g} ms {why}: "
                     + ("measured as noise all the same, there being no lead-in at rest" if kept
                        else "left out of the noise"))
    return lines


def search_lines(settlement: Settlement) -> list[str]:
    """V by order and the comparisons the order test decided by."""
    sweep = settlement.sweep
    costs = [(n, sweep.fits[n].cost) for n in sorted(sweep.fits)]
    lines = ["V by order: " + ", ".join(f"{n}: {v:.4g}" for n, v in costs if math.isfinite(v))] if costs else []
    for c in sweep.comparisons or []:
        if c.get("beaten"):
            lines.append(f"order {c['order']} beaten by {c['against']}: F {c['f']:.3g} > {c['f_critical']:.3g}, "
                         f"response change {c['response_change']:.2%}")
    return lines


def settle_lines(settlement: Settlement) -> list[str]:
    """The order and how it was chosen, the structure and why."""
    sweep = settlement.sweep
    lines = [f"order {settlement.order} ({settlement.settled.selection}): "
             f"{order_criterion(settlement.setup.significance)}"]
    if sweep.structure == Structure.ALL_POLE:
        why = sweep.why or "chosen over the model with free zeros"
        lines.append(f"structure: all-pole (no finite zeros, delay of either sign): {why}")
    return lines


def model_error_lines(error: ModelError) -> list[str]:
    """The model error on the final fit: its size and where it sits, or none."""
    if not error.significant:
        return [f"model error: none beyond the noise (residual {error.ratio:.3g}× the noise's)"]
    lo, hi = (v if math.isfinite(v) else 0.0 for v in error.range_hz)
    beta = error.drive_exponent if math.isfinite(error.drive_exponent) else 0.0
    return [f"model error: the residual is {error.ratio:.3g}× the noise's, {100.0 * error.rms_of_peak:.2g} % of the "
            f"peak RMS, mostly {lo / 1e3:.3g}–{hi / 1e3:.3g} kHz, its power ∝ |U|^{2 * beta:.2g} "
            "(0: independent of the drive): weighed in a second fit and drawn in the uncertainty"]


def claim_lines(modes: Sequence[Mode], resonance_above_hz: float | None) -> list[str]:
    """Each pole pair and whether it was claimed, and why; a resonance beyond the band."""
    lines = []
    for m in modes:
        if m.kind != ModeKind.COMPLEX:
            continue
        f_n = (m.natural_frequency_hz or 0.0) / 1e3
        why = ("claimed (inside the band)" if claimed(m)
               else "not claimed: a pole–zero doublet" if m.cancelled
               else f"not claimed: damped more than ζ = {RESONANCE_MAX_DAMPING:g}, no resonance" if m.supported
               else "not claimed: beyond the band, placed by the rise it gives inside it" if m.shapes_band
               else "not claimed: outside the supported band")
        lines.append(f"pole pair at {f_n:.4g} kHz, ζ {m.damping_ratio:.3g}: {why}")
    if resonance_above_hz:
        lines.append(f"resonance: > {resonance_above_hz / 1e3:.4g} kHz, in a null of the excitation")
    return lines


def stage_trail(prepared: PreparedRecord, settlement: Settlement, claim: Claim, levels: NoiseLevels,
                resonance_above_hz: float | None) -> Trail:
    """The trail of one identification from its stage results (`levels`: NoiseLevels.of the
    claim's response noise; `resonance_above_hz`: modes.resonance_above_hz of the claim's modes)."""
    parts = [(Stage.PREPARE, prepare_lines(prepared, levels, claim.model.delay_samples)),
             (Stage.SEARCH_ORDERS, search_lines(settlement)),
             (Stage.SETTLE, settle_lines(settlement)),
             (Stage.WEIGH_MODEL_ERROR, model_error_lines(settlement.model_error)),
             (Stage.CLAIM, claim_lines(claim.modes, resonance_above_hz))]
    return Trail(tuple(Step(stage, text) for stage, lines in parts for text in lines))

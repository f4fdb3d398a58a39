"""Dynamic compensation model (DCM), the paper's Eqs. (13)–(25), and applying it to data.

Design (checked against Eqs. (40)–(42) in PAPER-NOTES.md):
- zeros at the model poles p_i (they cancel the accelerometer's slow dynamics);
- the new poles make the compensated system respond r times faster than the slowest
  model pole: T'_rr = T'_r1 / r (in sample intervals), ω_e·T = 3/(ζ_e·T'_rr),
  |p_e| = exp(−3/T'_rr), θ_e = ω_e·T·sqrt(1 − ζ_e²), p_e = |p_e|·e^{±jθ_e}
  (a one-pole model gets the single real pole exp(−3/T'_rr) of Eq. (15));
- extra poles given by the user (both members of a conjugate pair) complete the
  denominator; the DCM must have as many poles as zeros to be causal. When fewer are
  given the rest are put at the ORIGIN: a pole at z = 0 is a one-sample delay, so the
  magnitude response is exactly the one designed and the output lags by that many
  samples (recorded as design["origin_poles"]). More poles than zeros is an error;
- the gain K makes G(1) = 1 (unit DC gain).

Filtering uses second-order sections with carried state, so a stream compensated block by
block equals the whole record compensated at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel, complex_pairs, from_pairs, load_json_object
from hopkinson.analysis.response import (
    DEFAULT_LEVELS,
    BandEdge,
    band_edges,
    fbsd_hz,
    frequency_response,
    model_output,
    pole_zero_frequencies_hz,
    response_times_samples,
    zpk_to_sos,
)
from scipy import signal

_CONJ_TOL = 1e-9
_MAX_STEP_SAMPLES = 4_000_000  # longest step response simulated for a rise time


def format_complex(value: complex) -> str:
    """A pole as people write it: 0.974+0.1396j (real poles without the j part)."""
    v = complex(value)
    return f"{v.real:.6g}" if v.imag == 0 else f"{v.real:.6g}{v.imag:+.6g}j"


def check_conjugate_pairs(values: np.ndarray, what: str) -> None:
    """Raise unless every complex value has its conjugate partner (real coefficients)."""
    v = list(np.atleast_1d(np.asarray(values, dtype=complex)))
    unmatched = [x for x in v if abs(x.imag) > _CONJ_TOL * max(1.0, abs(x))]
    while unmatched:
        x = unmatched.pop(0)
        partner = next((i for i, y in enumerate(unmatched) if abs(y - np.conj(x)) <= _CONJ_TOL * max(1.0, abs(x))), None)
        if partner is None:
            raise AnalysisError(
                f"{what}: {format_complex(x)} has no conjugate partner {format_complex(np.conj(x))}; "
                "list both members of every complex pair"
            )
        unmatched.pop(partner)


def check_inside_unit_circle(values: np.ndarray, what: str) -> None:
    """Raise unless every value lies strictly inside the unit circle (a stable pole)."""
    for x in np.atleast_1d(np.asarray(values, dtype=complex)):
        if not abs(x) < 1.0:
            raise AnalysisError(f"{what}: {format_complex(x)} is on or outside the unit circle (|p| = {abs(x):.6g}); the filter would be unstable")


def _real_poly(roots: np.ndarray) -> np.ndarray:
    """Coefficients (descending powers) of Π(z − r) for conjugate-complete roots."""
    return np.real(np.poly(roots)) if np.size(roots) else np.array([1.0])


@dataclass(frozen=True)
class DCM:
    """A compensator G(z) = gain·Π(z − zeros)/Π(z − poles) for one sample interval."""

    sample_interval_s: float
    zeros: np.ndarray
    poles: np.ndarray
    gain: float
    design: dict[str, Any] = field(default_factory=dict)  # how it was designed (ratio, ζ, …)

    def __post_init__(self) -> None:
        z = np.atleast_1d(np.asarray(self.zeros, dtype=complex))
        p = np.atleast_1d(np.asarray(self.poles, dtype=complex))
        if not self.sample_interval_s > 0:
            raise AnalysisError("DCM: sample_interval_s must be positive")
        if z.size > p.size:
            raise AnalysisError(f"DCM: {z.size} zeros but {p.size} poles; a causal DCM needs at least as many poles as zeros")
        check_conjugate_pairs(z, "DCM zeros")
        check_conjugate_pairs(p, "DCM poles")
        check_inside_unit_circle(p, "DCM pole")
        if not np.isfinite(self.gain) or self.gain == 0:
            raise AnalysisError("DCM: gain must be a finite non-zero number")
        object.__setattr__(self, "zeros", z)
        object.__setattr__(self, "poles", p)
        object.__setattr__(self, "gain", float(self.gain))

    @property
    def num(self) -> np.ndarray:
        """Numerator coefficients in descending powers of z (gain·Π(z − zᵢ))."""
        return self.gain * _real_poly(self.zeros)

    @property
    def den(self) -> np.ndarray:
        """Denominator coefficients in descending powers of z (monic Π(z − pᵢ))."""
        return _real_poly(self.poles)

    @property
    def b(self) -> np.ndarray:
        """Numerator in powers of z⁻¹ (for lfilter): num shifted by the relative degree."""
        return np.concatenate([np.zeros(self.poles.size - self.zeros.size), self.num])

    @property
    def a(self) -> np.ndarray:
        """Denominator in powers of z⁻¹ (for lfilter)."""
        return self.den

    @property
    def order(self) -> int:
        return int(self.poles.size)

    @property
    def dc_gain(self) -> float:
        return float(np.real(self.gain * np.prod(1 - self.zeros) / np.prod(1 - self.poles)))

    def sos(self) -> np.ndarray:
        """Second-order sections (what `apply` and `DcmStream` filter with)."""
        return zpk_to_sos(self.zeros, self.poles, self.gain)

    def frequency_response(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Complex G(e^{j2πfT}) at the given frequencies (Hz)."""
        f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
        _, h = signal.freqz_zpk(self.zeros, self.poles, self.gain, worN=f, fs=1.0 / self.sample_interval_s)
        return h

    def to_dict(self) -> dict[str, Any]:
        """The DCM JSON fields: num/den (descending powers of z), b/a (powers of z⁻¹), zpk."""
        return {
            "sample_interval_s": self.sample_interval_s,
            "order": self.order,
            "num": [float(x) for x in self.num],
            "den": [float(x) for x in self.den],
            "b": [float(x) for x in self.b],
            "a": [float(x) for x in self.a],
            "zeros": complex_pairs(self.zeros),
            "poles": complex_pairs(self.poles),
            "gain": self.gain,
            "dc_gain": self.dc_gain,
            "design": self.design,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "DCM") -> DCM:
        """Build from `to_dict` fields: zeros/poles/gain, or else num/den; errors name `source`."""
        if not isinstance(data, dict):
            raise AnalysisError(f"{source}: expected a JSON object with the DCM fields")
        if "sample_interval_s" not in data:
            raise AnalysisError(f"{source}: missing key 'sample_interval_s'")
        try:
            dt = float(data["sample_interval_s"])
        except (TypeError, ValueError):
            raise AnalysisError(f"{source}: sample_interval_s must be a number") from None
        design = data.get("design", {}) if isinstance(data.get("design", {}), dict) else {}
        try:
            if all(k in data for k in ("zeros", "poles", "gain")):
                zeros = from_pairs(data["zeros"], f"{source}: zeros")
                poles = from_pairs(data["poles"], f"{source}: poles")
                gain = float(data["gain"])
            elif "num" in data and "den" in data:
                num = np.trim_zeros(np.asarray(data["num"], dtype=float), "f")
                den = np.trim_zeros(np.asarray(data["den"], dtype=float), "f")
                if num.size == 0 or den.size == 0:
                    raise AnalysisError(f"{source}: num and den must have a non-zero coefficient")
                zeros = np.roots(num) if num.size > 1 else np.array([], dtype=complex)
                poles = np.roots(den) if den.size > 1 else np.array([], dtype=complex)
                gain = float(num[0] / den[0])
            else:
                raise AnalysisError(f"{source}: missing keys: a DCM needs zeros, poles and gain (or num and den)")
            return cls(dt, zeros, poles, gain, design)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, AnalysisError):
                raise AnalysisError(f"{exc}" if str(exc).startswith(source) else f"{source}: {exc}") from None
            raise AnalysisError(f"{source}: DCM coefficients must be numbers") from None


def load_dcm(path: str | Path) -> DCM:
    """Read a DCM JSON file written by `hopkinson dcm -o` (the DCM under "dcm" or at top level)."""
    data = load_json_object(path, "DCM")
    return DCM.from_dict(data.get("dcm", data), source=str(path))


def designed_poles(slowest_response_time_samples: float, ratio: float, damping: float, count: int) -> np.ndarray:
    """The new poles of Eqs. (22)–(25) (count = 2) or Eq. (15) (count = 1)."""
    target = slowest_response_time_samples / ratio  # T'_rr, Eq. (40)
    magnitude = np.exp(-3.0 / target)  # |p_e|, Eq. (22) with ζ_e·ω_e·T = 3/T'_rr
    if count == 1:
        return np.array([magnitude], dtype=complex)
    wt = 3.0 / (damping * target)  # ω_e·T, Eq. (23)
    theta = wt * np.sqrt(1.0 - damping**2)  # θ_e
    pe = magnitude * np.exp(1j * theta)
    return np.array([pe, np.conj(pe)])


def design_dcm(
    poles: np.ndarray,
    sample_interval_s: float,
    ratio: float,
    damping: float,
    extra_poles: Sequence[complex] | np.ndarray = (),
) -> DCM:
    """Design the DCM for a model with these discrete poles (see the module docstring).

    ratio: r, how many times faster than the slowest model pole the compensated system
    responds (T'_rr = T'_r1 / r); damping: ζ_e in (0, 1]; extra_poles: further poles, each
    complex one with its conjugate, all inside the unit circle.

    r acts on the decay envelope ζ·ω_n of the slowest pole, not on its frequency: the new
    poles have ω_e = r·ζ·ω_n/ζ_e. For a lightly damped accelerometer (ζ = 0.05) the
    compensated band is only wider than the resonance allows for r > ζ_e/ζ (≈ 14); with a
    matched damping (ζ_e = ζ) the band and the rise time scale by r (exactly in continuous
    time; within ~2 % at ω_e·T ≈ 0.1).
    """
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    if p.size == 0:
        raise AnalysisError("DCM: the model has no poles to compensate")
    check_conjugate_pairs(p, "model poles")
    check_inside_unit_circle(p, "model pole")
    if not (np.isfinite(ratio) and ratio > 0):
        raise AnalysisError(f"DCM: the response-time ratio must be positive, got {ratio}")
    if not (np.isfinite(damping) and 0 < damping <= 1):
        raise AnalysisError(f"DCM: the damping ratio ζ_e must be in (0, 1], got {damping}")
    if not sample_interval_s > 0:
        raise AnalysisError("DCM: the sample interval must be positive")
    extra = np.atleast_1d(np.asarray(extra_poles, dtype=complex))
    check_conjugate_pairs(extra, "extra poles")
    check_inside_unit_circle(extra, "extra pole")
    if np.any(np.abs(p - 1.0) < 1e-12):
        raise AnalysisError("DCM: a model pole at z = 1 cannot be compensated to unit DC gain")

    tr = response_times_samples(p)
    slowest = float(np.max(tr))
    new = designed_poles(slowest, ratio, damping, 1 if p.size == 1 else 2)
    all_poles = np.concatenate([new, extra])
    if all_poles.size > p.size:
        raise AnalysisError(
            f"DCM: {p.size} zeros (one per model pole) allow at most {p.size} poles, but the design gives "
            f"{new.size} and {extra.size} extra were listed; give at most {max(p.size - new.size, 0)} extra poles"
        )
    origin = p.size - all_poles.size
    all_poles = np.concatenate([all_poles, np.zeros(origin, dtype=complex)])
    gain = float(np.real(np.prod(1 - all_poles) / np.prod(1 - p)))  # G(1) = 1
    design = {
        "method": "Yang et al. Eqs. (13)-(25): zeros at the model poles, poles from r and zeta_e",
        "ratio": float(ratio),
        "damping": float(damping),
        "slowest_response_time_samples": slowest,
        "target_response_time_samples": slowest / ratio,
        "designed_poles": complex_pairs(new),
        "extra_poles": complex_pairs(extra),
        "origin_poles": int(origin),
    }
    return DCM(float(sample_interval_s), p, all_poles, gain, design)


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
    """10–90 % rise time in samples of a step response normalised to 1, first crossings
    interpolated linearly."""

    def first_crossing(level: float) -> float:
        idx = np.flatnonzero(step >= level)
        if idx.size == 0:
            raise AnalysisError("rise time: the step response never reaches 90 % of its final value")
        i = int(idx[0])
        if i == 0:
            return 0.0
        return (i - 1) + (level - step[i - 1]) / (step[i] - step[i - 1])

    return first_crossing(0.9) - first_crossing(0.1)


def _settling_time(step: np.ndarray, tolerance: float) -> float:
    """Samples until the normalised step response stays within 1 ± tolerance."""
    outside = np.flatnonzero(np.abs(step - 1.0) > tolerance)
    return 0.0 if outside.size == 0 else float(outside[-1] + 1)


def step_responses(model: DiscreteModel, dcm: DCM, n_samples: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit-step responses normalised to their final values: (model alone, model then DCM).

    The model's sections are delay-free (its input delay only shifts the curve). `n_samples`
    None: long enough for the slowest pole to settle (4 response times).
    """
    _same_interval(model, dcm)
    slowest = float(np.max(response_times_samples(np.concatenate([model.poles, dcm.poles]))))
    n = int(np.ceil(4 * slowest)) + model.b.size + dcm.order + 64 if n_samples is None else int(n_samples)
    if n > _MAX_STEP_SAMPLES:
        raise AnalysisError(
            f"step response: a pole settles in {slowest:.3g} samples; too slow to simulate a step response"
        )
    final = model.dc_gain
    if final == 0:
        raise AnalysisError("step response: the model has zero DC gain")
    alone = model_output(model, np.ones(n))
    both = signal.sosfilt(dcm.sos(), alone)
    return alone / final, both / (final * dcm.dc_gain)


@dataclass(frozen=True)
class StepComparison:
    """The normalised step responses of the model alone and followed by the DCM (one simulation,
    `compare_steps`) and the times read off them, in samples: (without, with the DCM)."""

    alone: np.ndarray
    both: np.ndarray

    def rise_times_samples(self) -> tuple[float, float]:
        """10–90 % rise times."""
        return _rise_time(self.alone), _rise_time(self.both)

    def rise_time_ratio(self) -> float:
        """Uncompensated ÷ compensated 10–90 % rise time (> 1 when the DCM speeds it up)."""
        before, after = self.rise_times_samples()
        if after <= 0:
            raise AnalysisError("rise time: the compensated step response rises within one sample")
        return before / after

    def settling_times_samples(self, tolerance: float = 0.05) -> tuple[float, float]:
        """Samples to settle within ±5 % of the final value."""
        return _settling_time(self.alone, tolerance), _settling_time(self.both, tolerance)

    def settling_time_ratio(self, tolerance: float = 0.05) -> float:
        """Uncompensated ÷ compensated time to settle within ±5 % (the paper's response time T_r).

        For a lightly damped sensor this is the figure that shows what the DCM buys: the sensor
        rises fast (its 10–90 % rise time is short) but rings for hundreds of samples.
        """
        before, after = self.settling_times_samples(tolerance)
        return before / max(after, 1.0)


def compare_steps(model: DiscreteModel, dcm: DCM) -> StepComparison:
    """Simulate both step responses once (`step_responses`) for every time and ratio read off them."""
    return StepComparison(*step_responses(model, dcm))


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


class DcmStream:
    """Apply a DCM block by block, carrying the filter state between blocks.

    initial="rest": the filter starts from zero state (as lfilter does by default);
    initial="steady": it starts in the steady state for a constant input equal to the
    first sample (no start-up transient on a record with an offset).
    """

    def __init__(self, dcm: DCM, initial: str = "rest") -> None:
        if initial not in ("rest", "steady"):
            raise AnalysisError(f"DCM stream: initial must be 'rest' or 'steady', got {initial!r}")
        self.dcm = dcm
        self.initial = initial
        self._sos = dcm.sos()
        self._zi: np.ndarray | None = None
        self.samples_processed = 0

    def reset(self) -> None:
        """Forget the carried state: the next block starts a new stream."""
        self._zi = None
        self.samples_processed = 0

    def process(self, block: np.ndarray) -> np.ndarray:
        """Compensate the next block of samples and return it (same length)."""
        x = np.asarray(block, dtype=float)
        if x.ndim != 1:
            raise AnalysisError("DCM stream: a block must be a 1-D array of samples")
        if x.size == 0:
            return x.copy()
        if not np.all(np.isfinite(x)):
            raise AnalysisError(f"DCM stream: NaN or infinite sample at {self.samples_processed + int(np.flatnonzero(~np.isfinite(x))[0])}")
        if self._zi is None:
            zi = signal.sosfilt_zi(self._sos) * x[0] if self.initial == "steady" else np.zeros((self._sos.shape[0], 2))
            self._zi = zi
        y, self._zi = signal.sosfilt(self._sos, x, zi=self._zi)
        self.samples_processed += x.size
        return y


def apply(dcm: DCM, data: np.ndarray, initial: str = "rest", block_samples: int | None = None) -> np.ndarray:
    """Compensate a record: at once, or in blocks of `block_samples` through a DcmStream.

    Both give the same samples (the stream carries the filter state between blocks).
    """
    stream = DcmStream(dcm, initial)
    x = np.asarray(data, dtype=float)
    if block_samples is None:
        return stream.process(x)
    if block_samples < 1:
        raise AnalysisError(f"DCM: block_samples must be at least 1, got {block_samples}")
    return np.concatenate([stream.process(x[i : i + block_samples]) for i in range(0, x.size, block_samples)] or [x[:0]])


DEFAULT_WIDENING = 3.0  # automatic design: compensated ±5 % band this many times the model's


def ratio_for_widening(
    model: DiscreteModel,
    damping: float = 0.707,
    widening: float = DEFAULT_WIDENING,
    extra_poles: Sequence[complex] | np.ndarray = (),
) -> float:
    """The smallest response-time ratio r whose DCM widens the ±5 % FBSD by `widening`.

    The paper leaves r to the engineer. r scales the decay envelope ζ·ω_n of the slowest
    pole (see design_dcm), so the same r widens a lightly damped sensor's band far less than
    a well damped one's; choosing r for a target band is what a calibration engineer wants.
    Scans r upwards on a log grid (1 … 2000) until the band reaches the target and refines by
    bisection; when no r reaches it, returns the r of the widest band found. Only the ±5 %
    edge is searched for (the ±10 % one would cost as much again and is not used).
    """
    if not widening > 1:
        raise AnalysisError(f"DCM: the band widening must be > 1, got {widening}")
    level = (0.05,)
    target = widening * fbsd_hz(model, level)["5"]
    poles = model.poles

    def band(r: float) -> float:
        try:
            dcm = design_dcm(poles, model.sample_interval_s, r, damping, extra_poles)
            return compensated_fbsd_hz(model, dcm, level)["5"]
        except AnalysisError:
            return 0.0

    grid = np.geomspace(1.0, 2000.0, 60)
    bands: list[float] = []
    for r in grid:
        bands.append(band(r))
        if bands[-1] >= target:
            break
    else:
        return float(grid[int(np.argmax(bands))])
    i = len(bands) - 1
    if i == 0:
        return float(grid[0])
    lo, hi = float(grid[i - 1]), float(grid[i])
    for _ in range(30):  # bisection on a possibly non-smooth function: no brentq
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if band(mid) < target else (lo, mid)
        if hi / lo < 1.0005:
            break
    return hi

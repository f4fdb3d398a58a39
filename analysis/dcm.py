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

A DCM may end in a linear-phase FIR stage (`DCM.fir`, taps in powers of z⁻¹): the band limit
analysis.dcm_design puts after the paper's design. The pole-zero part is the paper's; the
whole filter (num/den, b/a, its response, DC gain, delay and noise gain) includes the stage.

Filtering uses second-order sections with carried state, then the FIR stage with its own, so
a stream compensated block by block equals the whole record compensated at once. A stream
can also remove the latency (`DcmStream(align=True)`): the output is advanced by
`DCM.latency_samples` (whole samples held back, the fraction by a windowed-sinc
fractional-delay FIR), so it lines up in time with the reference; `flush()` returns the
held-back tail.

Which poles a shot lets the DCM cancel, the automatic ratio, the band limit and the noise
gain bound live in analysis.dcm_design; the check of a DCM on its own shot in
analysis.compensation.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import signal

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel, complex_pairs, from_pairs, load_json_object
from hopkinson.analysis.params import CONJUGATE_TOLERANCE
from hopkinson.analysis.records import MAX_ABS_VALUE
from hopkinson.analysis.response import (
    DEFAULT_LEVELS,
    BandEdge,
    band_edges,
    frequency_response,
    model_output,
    pole_zero_frequencies_hz,
    response_times_samples,
    zpk_to_sos,
)

_CONJ_TOL = CONJUGATE_TOLERANCE  # the rule AnalysisParams.check() applies to extra poles too
_MAX_STEP_SAMPLES = 4_000_000  # longest step response simulated for a rise time


def format_complex(value: complex) -> str:
    """A pole as people write it: 0.974+0.1396j (real poles without the j part)."""
    v = complex(value)
    return f"{v.real:.6g}" if v.imag == 0 else f"{v.real:.6g}{v.imag:+.6g}j"


def parse_complex(text: str, option: str) -> complex:
    """One pole such as 0.974+0.1396j, 0.974-0.1396i or 0.5 (the inverse of `format_complex`);
    AnalysisError naming `option` otherwise."""
    raw = text.strip().replace(" ", "")
    if not raw:
        raise AnalysisError(f"{option}: empty pole in the list (write poles like 0.974+0.1396j, comma-separated)")
    try:
        value = complex(raw.replace("i", "j").replace("I", "j").replace("J", "j"))
    except ValueError:
        raise AnalysisError(f"{option}: {text.strip()!r} is not a complex number (write poles like 0.974+0.1396j)") from None
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise AnalysisError(f"{option}: {text.strip()!r} is not a finite number")
    return value


def parse_poles(text: str, option: str) -> np.ndarray:
    """A comma-separated list of poles (what `hopkinson dcm --poles` and the panel accept)."""
    return np.array([parse_complex(part, option) for part in text.split(",")], dtype=complex)


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
    least-squares slope through the origin of its unwrapped phase against ω·T (256 points).

    The group delay exactly at DC would do for a clean model, but a slow spare pole-zero pair of
    a fit (a doublet at a few hundred Hz) moves it by tens of samples while changing nothing a
    shock pulse contains; the slope over the band the compensated system passes flat is the
    delay its content sees.
    """
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


def _real_poly(roots: np.ndarray) -> np.ndarray:
    """Coefficients (descending powers) of Π(z − r) for conjugate-complete roots."""
    return np.real(np.poly(roots)) if np.size(roots) else np.array([1.0])


@dataclass(frozen=True)
class DCM:
    """A compensator G(z) = gain·Π(z − zeros)/Π(z − poles) · Σ fir[k]·z⁻ᵏ for one sample
    interval (fir None: no FIR stage)."""

    sample_interval_s: float
    zeros: np.ndarray
    poles: np.ndarray
    gain: float
    design: dict[str, Any] = field(default_factory=dict)  # how it was designed (ratio, ζ, …)
    # Total latency of the compensated output behind the reference, in samples: the identified
    # channel delay plus the low-frequency group delay of model × DCM (analysis.dcm_design).
    # None: not known (a DCM from poles alone): the DCM's own group delay is used.
    latency_samples: float | None = None
    # A FIR stage after the pole-zero part (taps in powers of z⁻¹; None: none): the band limit.
    # Kept as taps, not as zeros: the roots of a 100-tap polynomial do not survive rounding.
    fir: np.ndarray | None = None

    def __post_init__(self) -> None:
        z = np.atleast_1d(np.asarray(self.zeros, dtype=complex))
        p = np.atleast_1d(np.asarray(self.poles, dtype=complex))
        if not (math.isfinite(self.sample_interval_s) and self.sample_interval_s > 0):
            raise AnalysisError("DCM: sample_interval_s must be a positive number")
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(p))):
            raise AnalysisError("DCM: its zeros and poles must be finite numbers")
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
        if self.fir is not None:
            taps = np.asarray(self.fir, dtype=float)
            if taps.ndim != 1 or taps.size == 0 or not np.all(np.isfinite(taps)):
                raise AnalysisError("DCM: fir must be a non-empty list of finite numbers (taps in powers of z⁻¹)")
            if abs(float(np.sum(taps))) < 1e-12 * float(np.max(np.abs(taps))):
                raise AnalysisError("DCM: the FIR stage has zero DC gain: it would remove the acceleration itself")
            object.__setattr__(self, "fir", taps)
        with np.errstate(over="ignore", invalid="ignore"):
            finite = bool(np.all(np.isfinite(self.num)) and math.isfinite(self.dc_gain))
        if not finite:
            raise AnalysisError(
                f"DCM: gain {self.gain:g} with these zeros gives coefficients that are not finite numbers (overflow)"
            )
        if np.any(np.abs(1 - z) < 1e-12):
            raise AnalysisError("DCM: a zero at z = 1 gives it zero DC gain: it would remove the acceleration itself")
        if self.latency_samples is not None:
            if not math.isfinite(self.latency_samples):
                raise AnalysisError("DCM: latency must be a finite number of samples")
            object.__setattr__(self, "latency_samples", float(self.latency_samples))

    @property
    def pole_zero_num(self) -> np.ndarray:
        """The pole-zero part's numerator, descending powers of z: gain·Π(z − zᵢ)."""
        return self.gain * _real_poly(self.zeros)

    @property
    def pole_zero_den(self) -> np.ndarray:
        """The pole-zero part's denominator, descending powers of z: monic Π(z − pᵢ)."""
        return _real_poly(self.poles)

    @property
    def num(self) -> np.ndarray:
        """Numerator coefficients in descending powers of z (the pole-zero part's, times the FIR's
        Σ fir[k]·z^(N−1−k))."""
        core = self.pole_zero_num
        return core if self.fir is None else np.convolve(core, self.fir)

    @property
    def den(self) -> np.ndarray:
        """Denominator coefficients in descending powers of z (the pole-zero part's, times z^(N−1)
        with an N-tap FIR stage)."""
        core = self.pole_zero_den
        return core if self.fir is None else np.concatenate([core, np.zeros(self.fir.size - 1)])

    @property
    def b(self) -> np.ndarray:
        """Numerator in powers of z⁻¹ (for lfilter): num shifted by the relative degree."""
        return np.concatenate([np.zeros(self.poles.size - self.zeros.size), self.num])

    @property
    def a(self) -> np.ndarray:
        """Denominator in powers of z⁻¹ (for lfilter): the pole-zero part's (the FIR adds none)."""
        return self.pole_zero_den

    @property
    def order(self) -> int:
        return int(self.poles.size)

    @property
    def dc_gain(self) -> float:
        core = float(np.real(self.gain * np.prod(1 - self.zeros) / np.prod(1 - self.poles)))
        return core if self.fir is None else core * float(np.sum(self.fir))

    @property
    def group_delay_samples(self) -> float:
        """The DCM's own group delay at DC, in samples (closed form, exact).

        Each factor (z − a) of G at z = e^{jω} turns the phase by arg(e^{jω} − a), whose
        derivative at ω = 0 is Re(1/(1 − a)); so τ(0) = Σ_poles Re 1/(1 − p) − Σ_zeros Re 1/(1 − z)
        (a pole at the origin is one sample). scipy.signal.group_delay evaluates the same from
        polynomial coefficients numerically and warns at singular points; this needs neither.
        """
        core = dc_group_delay_samples(self.zeros, self.poles)
        if self.fir is None:
            return core
        return core + float(np.dot(np.arange(self.fir.size), self.fir) / np.sum(self.fir))

    @property
    def latency_s(self) -> float:
        """Total latency of the compensated output (s): the stored one, else the DCM's own."""
        samples = self.group_delay_samples if self.latency_samples is None else self.latency_samples
        return samples * self.sample_interval_s

    def noise_gain(self) -> float:
        """RMS amplification of white noise at the DCM's rate: sqrt(Σ h[k]²) over its impulse
        response h (the H2 norm; equal to the RMS of |G| over the band 0 … Nyquist)."""
        h = self.impulse_response()
        return float(np.sqrt(np.dot(h, h)))

    def impulse_response(self) -> np.ndarray:
        """h[k] until it has decayed below 1e-10 of its start (error if a pole is too slow)."""
        slowest = float(np.max(np.abs(self.poles))) if self.poles.size else 0.0
        tail = 0 if slowest == 0 else math.ceil(2 * math.log(1e-10) / math.log(slowest))
        n = self.order + 16 + tail
        if n > _MAX_STEP_SAMPLES:
            raise AnalysisError(f"DCM: a pole at |p| = {slowest:.9g} decays too slowly to evaluate its noise gain")
        impulse = np.zeros(n)
        impulse[0] = 1.0
        return self.filter(impulse if self.fir is None else np.concatenate([impulse, np.zeros(self.fir.size - 1)]))

    def sos(self) -> np.ndarray:
        """Second-order sections of the pole-zero part (what `apply` and `DcmStream` filter
        with, then the FIR stage)."""
        return zpk_to_sos(self.zeros, self.poles, self.gain)

    def filter(self, x: np.ndarray, axis: int = -1) -> np.ndarray:
        """The whole DCM from rest along `axis`: the sections, then the FIR stage."""
        y = signal.sosfilt(self.sos(), x, axis=axis)
        return y if self.fir is None else signal.lfilter(self.fir, [1.0], y, axis=axis)

    def frequency_response(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Complex G(e^{j2πfT}) at the given frequencies (Hz)."""
        f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
        fs = 1.0 / self.sample_interval_s
        _, h = signal.freqz_zpk(self.zeros, self.poles, self.gain, worN=f, fs=fs)
        if self.fir is not None:
            h = h * signal.freqz(self.fir, [1.0], worN=f, fs=fs)[1]
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
            "group_delay_s": self.group_delay_samples * self.sample_interval_s,
            "latency_s": self.latency_s,
            "noise_gain": self.noise_gain(),
            "design": self.design,
            **({} if self.fir is None else {"fir": [float(x) for x in self.fir]}),
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
        fir = data.get("fir")
        if fir is not None and not (isinstance(fir, list) and fir):
            raise AnalysisError(f"{source}: fir must be a non-empty list of taps")
        try:
            fir = None if fir is None else np.asarray(fir, dtype=float)
            if all(k in data for k in ("zeros", "poles", "gain")):
                zeros = from_pairs(data["zeros"], f"{source}: zeros")
                poles = from_pairs(data["poles"], f"{source}: poles")
                gain = float(data["gain"])
                if "num" in data and "den" in data:  # both forms: they must say the same (one was edited?)
                    _check_same_filter(zeros, poles, gain, data["num"], data["den"], source, fir)
            elif fir is not None:
                raise AnalysisError(f"{source}: a DCM with a FIR stage needs its zeros, poles and gain")
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
            latency = data.get("latency_s")
            latency_samples = None if latency is None else float(latency) / dt
            return cls(dt, zeros, poles, gain, design, latency_samples, fir)
        except (TypeError, ValueError, ZeroDivisionError) as exc:
            if isinstance(exc, AnalysisError):
                raise AnalysisError(f"{exc}" if str(exc).startswith(source) else f"{source}: {exc}") from None
            raise AnalysisError(f"{source}: DCM coefficients must be numbers") from None


def _check_same_filter(zeros: np.ndarray, poles: np.ndarray, gain: float, num: Any, den: Any, source: str,
                       fir: np.ndarray | None = None) -> None:
    """AnalysisError when num/den are not the filter that zeros/poles/gain (and the FIR stage)
    give (to 1e-6 of the largest coefficient): a file edited in one form only would otherwise
    be read silently."""
    want_num = np.real_if_close(gain * np.poly(zeros)) if zeros.size else np.array([gain])
    want_den = np.real_if_close(np.poly(poles)) if poles.size else np.array([1.0])
    if fir is not None:
        want_num = np.convolve(want_num, fir)
        want_den = np.concatenate([want_den, np.zeros(fir.size - 1)])
    got_num, got_den = np.asarray(num, dtype=float), np.asarray(den, dtype=float)
    if got_den.size and got_den[0] != 0:
        got_num, got_den = got_num / got_den[0], got_den / got_den[0]
    for got, want, name in ((got_num, want_num, "num"), (got_den, want_den, "den")):
        got = np.trim_zeros(got, "f")
        if got.shape != np.shape(want) or not np.allclose(got, want, rtol=1e-6,
                                                          atol=1e-6 * float(np.max(np.abs(want)))):
            raise AnalysisError(f"{source}: {name} is not the filter its zeros, poles and gain give (edited in one "
                                "form only?): keep one form, or make both agree")


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
    if n + lead > _MAX_STEP_SAMPLES:
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
        """Uncompensated ÷ compensated time to settle within ±5 % (the paper's response time T_r).

        For a lightly damped sensor this is the figure that shows what the DCM buys: the sensor
        rises fast (its 10–90 % rise time is short) but rings for hundreds of samples.
        """
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


# Fractional part of a latency removed by a windowed-sinc FIR of 2·16 + 1 taps (Kaiser, β = 8):
# its response is within 2e-4 of the exact fractional delay below 0.3 × the sample rate
# (measured), far above where a compensated record (band-limited by its DCM) has content.
_ALIGN_HALF_TAPS = 16
_ALIGN_KAISER_BETA = 8.0


def fractional_delay_fir(delay_samples: float, half_taps: int = _ALIGN_HALF_TAPS) -> np.ndarray:
    """Taps of an FIR that delays by `delay_samples` (within ±1 of `half_taps`): a Kaiser-windowed
    sinc centred on the delay, normalised to unit DC gain.

    Written here because scipy.signal designs linear-phase FIRs only with integer or half-integer
    delays (firwin); a fractional delay needs the sinc sampled off its centre.
    """
    k = np.arange(2 * half_taps + 1, dtype=float) - delay_samples
    window = np.i0(_ALIGN_KAISER_BETA * np.sqrt(np.clip(1 - (k / (half_taps + 1)) ** 2, 0, None))) / np.i0(
        _ALIGN_KAISER_BETA
    )
    taps = np.sinc(k) * window
    return taps / np.sum(taps)


class DcmStream:
    """Apply a DCM block by block, carrying the filter state between blocks.

    initial="rest": the filter starts from zero state (as lfilter does by default);
    initial="steady": it starts in the steady state for a constant input equal to the
    first sample (no start-up transient on a record with an offset).
    align=True: the output is advanced by the DCM's latency (`DCM.latency_samples`, else its
    own group delay) so that it lines up with the reference: the whole samples are held back
    at the start (`process` returns fewer samples than it was given until they are used up),
    the fraction is removed by a fractional-delay FIR, and `flush()` returns the tail,
    computed by continuing the input with its last sample. A latency below zero (a response
    that leads its reference by more than the FIR's half length: the channels' skew, which the
    latency includes) is removed by delaying the output instead: it starts with that many
    samples of its initial level, and its last ones, past the input's length, are dropped.
    Every output is checked: a non-finite sample (an overflowing DCM) is an AnalysisError.
    """

    def __init__(self, dcm: DCM, initial: str = "rest", align: bool = False) -> None:
        if initial not in ("rest", "steady"):
            raise AnalysisError(f"DCM stream: initial must be 'rest' or 'steady', got {initial!r}")
        self.dcm = dcm
        self.initial = initial
        self.align = align
        self._sos = dcm.sos()
        self._fir: np.ndarray | None = None
        self._hold = 0
        self._delay = 0  # output samples to delay by (a latency below zero)
        if align:
            latency = dcm.latency_s / dcm.sample_interval_s
            whole = math.floor(latency)
            fraction = latency - whole
            if fraction > 1e-9:
                self._fir = fractional_delay_fir(_ALIGN_HALF_TAPS - fraction)
                whole += _ALIGN_HALF_TAPS
            self._hold, self._delay = max(whole, 0), max(-whole, 0)
        self.reset()

    @property
    def held_samples(self) -> int:
        """Output samples held back at the start to remove the latency (0 without align)."""
        return self._hold

    @property
    def delayed_samples(self) -> int:
        """Output samples the output is delayed by to remove a latency below zero (0 otherwise)."""
        return self._delay

    def reset(self) -> None:
        """Forget the carried state: the next block starts a new stream."""
        self._zi: np.ndarray | None = None
        self._band_zi: np.ndarray | None = None  # the DCM's own FIR stage
        self._fir_zi: np.ndarray | None = None  # the alignment's fractional delay
        self._to_drop = self._hold
        self._queue: np.ndarray | None = None  # the delay line (None: not started)
        self._last = 0.0
        self.samples_processed = 0
        self.samples_returned = 0

    def process(self, block: np.ndarray) -> np.ndarray:
        """Compensate the next block of samples and return what is ready (the same length
        without align)."""
        x = np.asarray(block, dtype=float)
        if x.ndim != 1:
            raise AnalysisError("DCM stream: a block must be a 1-D array of samples")
        if x.size == 0:
            return x.copy()
        if not np.all(np.isfinite(x)):
            raise AnalysisError(f"DCM stream: NaN or infinite sample at {self.samples_processed + int(np.flatnonzero(~np.isfinite(x))[0])}")
        y = self._filter(x)
        self.samples_processed += x.size
        self._last = float(x[-1])
        return self._release(y)

    def flush(self) -> np.ndarray:
        """The held-back tail (align only): the input continued by its last sample through the
        filter, so the whole output is as long as the whole input. Ends the stream."""
        missing = self.samples_processed - self.samples_returned
        if missing <= 0:
            return np.zeros(0)
        y = self._release(self._filter(np.full(self._hold, self._last)))
        return y[:missing]

    def _filter(self, x: np.ndarray) -> np.ndarray:
        if self._zi is None:
            steady = self.initial == "steady"
            self._zi = signal.sosfilt_zi(self._sos) * x[0] if steady else np.zeros((self._sos.shape[0], 2))
        y, self._zi = signal.sosfilt(self._sos, x, zi=self._zi)
        band = self.dcm.fir
        if band is not None:
            if self._band_zi is None:
                level = y[0] if self.initial == "steady" else 0.0
                self._band_zi = signal.lfilter_zi(band, [1.0]) * level
            y, self._band_zi = signal.lfilter(band, [1.0], y, zi=self._band_zi)
        if self._fir is not None:
            if self._fir_zi is None:
                level = y[0] if self.initial == "steady" else 0.0
                self._fir_zi = signal.lfilter_zi(self._fir, [1.0]) * level
            y, self._fir_zi = signal.lfilter(self._fir, [1.0], y, zi=self._fir_zi)
        bad = ~(np.abs(y) <= MAX_ABS_VALUE)  # NaN and ±inf are bad too
        if np.any(bad):
            at = self.samples_processed + int(np.flatnonzero(bad)[0])
            raise AnalysisError(
                f"the DCM's output is not a finite number within ±{MAX_ABS_VALUE:g} from input sample {at} on (it "
                f"overflows: gain {self.dcm.gain:g}, DC gain {self.dcm.dc_gain:g}); this DCM cannot compensate "
                "this record"
            )
        return y

    def _release(self, y: np.ndarray) -> np.ndarray:
        if self._delay:
            if self._queue is None:  # the initial level: the filter's first output from rest or steady state
                self._queue = np.full(self._delay, y[0] if self.initial == "steady" else 0.0)
            line = np.concatenate([self._queue, y])
            y, self._queue = line[: y.size], line[y.size :]
        if self._to_drop:
            drop = min(self._to_drop, y.size)
            self._to_drop -= drop
            y = y[drop:]
        self.samples_returned += y.size
        return y


def apply_rows(dcm: DCM, rows: np.ndarray, align: bool = False) -> np.ndarray:
    """`apply(dcm, row, align=align)` from rest for every row of `rows` (records of one length)
    in one filter call per stage: the same sections, FIR, held samples and tail (the input
    continued by its last sample) as DcmStream, so the same numbers; for many records (the
    compensated peak's model draws) without a DcmStream, its sections and its FIR per record."""
    x = np.atleast_2d(np.asarray(rows, dtype=float))
    stream = DcmStream(dcm, "rest", align)
    if x.shape[1] == 0:
        return x.copy()
    if not np.all(np.isfinite(x)):
        raise AnalysisError("DCM: NaN or infinite sample in a record to compensate")
    n, hold, delay = x.shape[1], stream.held_samples, stream.delayed_samples
    if hold:
        x = np.concatenate([x, np.repeat(x[:, -1:], hold, axis=1)], axis=1)
    if delay:  # from rest: the delayed output starts at zero (DcmStream._release)
        x = np.concatenate([np.zeros((x.shape[0], delay)), x], axis=1)
    y = dcm.filter(x, axis=1)
    if stream._fir is not None:
        y = signal.lfilter(stream._fir, [1.0], y, axis=1)
    bad = ~(np.abs(y) <= MAX_ABS_VALUE)
    if np.any(bad):
        raise AnalysisError(
            f"the DCM's output is not a finite number within ±{MAX_ABS_VALUE:g} (it overflows: gain {dcm.gain:g}, DC "
            f"gain {dcm.dc_gain:g}); this DCM cannot compensate this record"
        )
    return y[:, hold : hold + n]


def apply(
    dcm: DCM, data: np.ndarray, initial: str = "rest", block_samples: int | None = None, align: bool = False
) -> np.ndarray:
    """Compensate a record: at once, or in blocks of `block_samples` through a DcmStream.

    Both give the same samples (the stream carries the filter state between blocks). align:
    the output is advanced by the DCM's latency (see DcmStream), same length as the input.
    """
    stream = DcmStream(dcm, initial, align)
    x = np.asarray(data, dtype=float)
    if block_samples is not None and block_samples < 1:
        raise AnalysisError(f"DCM: block_samples must be at least 1, got {block_samples}")
    step = x.size if block_samples is None else block_samples
    parts = [stream.process(x[i : i + step]) for i in range(0, x.size, max(step, 1))]
    parts.append(stream.flush())
    return np.concatenate(parts) if x.size else x.copy()

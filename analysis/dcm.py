"""The dynamic compensation model (DCM), the paper's Eqs. (13)–(25): the filter object, its
JSON file and its design from a model's poles.

G(z) = K·Π(z − p_i)/Π(z − p_e) · FIR: zeros at the model's poles, new poles r times faster than
the slowest model pole, poles at the origin to make it causal, K for unit DC gain, and an
optional linear-phase FIR stage (the band limit of analysis.dcm_design). Why it is built so:
docs/decisions/0020-dcm-design-and-streaming.md. Applying it: analysis.dcm_stream; its figures:
analysis.dcm_figures.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy import signal

from hopkinson.analysis.dcm_figures import MAX_SIMULATED_SAMPLES
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.group_delay import dc_group_delay_samples
from hopkinson.analysis.model import complex_pairs, from_pairs, load_json_object
from hopkinson.analysis.pole_checks import check_conjugate_pairs, check_inside_unit_circle
from hopkinson.analysis.response import response_times_samples, zpk_to_sos


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

    def with_latency(self, latency_samples: float) -> DCM:
        """The same DCM with this latency (samples): `dataclasses.replace(dcm, latency_samples=…)`
        without validating the filter again (the ratio search re-aligns each candidate)."""
        if not math.isfinite(latency_samples):
            raise AnalysisError("DCM: latency must be a finite number of samples")
        moved = copy.copy(self)
        object.__setattr__(moved, "latency_samples", float(latency_samples))
        return moved

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
        """The DCM's own group delay at DC, in samples: Σ_poles Re 1/(1 − p) − Σ_zeros Re 1/(1 − z),
        plus the FIR stage's centre of mass (exact; scipy.signal.group_delay would warn at
        singular points)."""
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
        response h (the H2 norm; equal to the RMS of |G| over the band 0 … Nyquist). Computed
        once per filter (its zeros, poles, gain and taps: `_filter_key`), however many DCMs
        `dataclasses.replace` makes of it."""
        return _impulse_norms(*self._filter_key())[0]

    def l1_gain(self) -> float:
        """Σ |h[k]| over its impulse response: no output from rest exceeds this × the input's
        largest magnitude (computed once per filter, as the noise gain)."""
        return _impulse_norms(*self._filter_key())[1]

    def _filter_key(self) -> tuple[bytes, bytes, float, bytes | None]:
        """What the filter is (not its design notes or latency), as the caches' key."""
        return (self.zeros.tobytes(), self.poles.tobytes(), self.gain,
                None if self.fir is None else self.fir.tobytes())

    def impulse_response(self) -> np.ndarray:
        """h[k] until it has decayed below 1e-10 of its start (error if a pole is too slow)."""
        return _impulse_response(*self._filter_key())

    def sos(self) -> np.ndarray:
        """Second-order sections of the pole-zero part (what `apply` and `DcmStream` filter
        with, then the FIR stage); built once per filter (`_filter_key`), a copy returned."""
        return _sections(*self._filter_key()[:3]).copy()

    def filter(self, x: np.ndarray, axis: int = -1) -> np.ndarray:
        """The whole DCM from rest along `axis`: the sections, then the FIR stage."""
        return _filtered(self.sos(), self.fir, x, axis)

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


# The ratio search designs, filters and re-aligns the same filters many times (dataclasses.replace
# makes new DCMs of one filter): its sections and noise gain are kept per filter, keyed by its
# coefficients' bytes. An entry is a few hundred bytes, up to ~16 kB with a 1001-tap band limit
# (its taps in the key, its impulse response's norms): 256 of them stay within a few MB.
_FILTER_CACHE_SIZE = 256


@lru_cache(maxsize=_FILTER_CACHE_SIZE)
def _sections(zeros: bytes, poles: bytes, gain: float) -> np.ndarray:
    sos = zpk_to_sos(np.frombuffer(zeros, dtype=complex).copy(), np.frombuffer(poles, dtype=complex).copy(), gain)
    sos.setflags(write=False)
    return sos


@lru_cache(maxsize=_FILTER_CACHE_SIZE)
def _impulse_norms(zeros: bytes, poles: bytes, gain: float, fir: bytes | None) -> tuple[float, float]:
    """(noise gain, Σ |h[k]|) of the filter `DCM._filter_key` names."""
    h = _impulse_response(zeros, poles, gain, fir)
    return float(np.sqrt(np.dot(h, h))), float(np.sum(np.abs(h)))


def _impulse_response(zeros: bytes, poles: bytes, gain: float, fir: bytes | None) -> np.ndarray:
    """DCM.impulse_response of the filter `DCM._filter_key` names."""
    p = np.frombuffer(poles, dtype=complex)
    slowest = float(np.max(np.abs(p))) if p.size else 0.0
    tail = 0 if slowest == 0 else math.ceil(2 * math.log(1e-10) / math.log(slowest))
    n = p.size + 16 + tail
    if n > MAX_SIMULATED_SAMPLES:
        raise AnalysisError(f"DCM: a pole at |p| = {slowest:.9g} decays too slowly to evaluate its noise gain")
    taps = None if fir is None else np.frombuffer(fir, dtype=float)
    impulse = np.zeros(n if taps is None else n + taps.size - 1)
    impulse[0] = 1.0
    return _filtered(_sections(zeros, poles, gain).copy(), taps, impulse, -1)


def _filtered(sos: np.ndarray, fir: np.ndarray | None, x: np.ndarray, axis: int) -> np.ndarray:
    """x through the sections from rest, then the FIR stage (None: none)."""
    y = signal.sosfilt(sos, x, axis=axis)
    return y if fir is None else signal.lfilter(fir, [1.0], y, axis=axis)


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
    """The paper's DCM (`designed_zpk`) as a DCM."""
    return DCM(float(sample_interval_s), *designed_zpk(poles, sample_interval_s, ratio, damping, extra_poles))


def designed_zpk(
    poles: np.ndarray,
    sample_interval_s: float,
    ratio: float,
    damping: float,
    extra_poles: Sequence[complex] | np.ndarray = (),
) -> tuple[np.ndarray, np.ndarray, float, dict[str, Any]]:
    """(zeros, poles, gain, design) of the paper's DCM for a model with these discrete poles: zeros at them, new poles from r and
    ζ_e, the rest at the origin, unit DC gain.

    ratio: r, how many times faster than the slowest model pole the compensated system responds
    (T'_rr = T'_r1 / r; r acts on the decay envelope ζ·ω_n, docs/decisions/0020); damping: ζ_e in
    (0, 1]; extra_poles: further poles, each complex one with its conjugate, inside the unit
    circle. The design (ratio, ζ_e, designed poles, …) is what `DCM.design` records.
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
    return p, all_poles, gain, design

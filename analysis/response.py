"""Frequency response, band of small distortion (FBSD), pole analysis and d → c conversion.

The FBSD at level L is the first frequency from DC at which the normalised gain
|H(f)/H(0)| leaves the band 1 ± L (the paper's ±5 % and ±10 % bands). The test is
two-sided: near a lightly damped resonance the gain rises above 1 + L long before it ever
falls below 1 − L (a one-sided "bandwidth", e.g. python-control's, is ~4.6× too wide).

A band edge that is never reached below the highest frequency examined (Nyquist for a
discrete model) is reported AT that frequency with `crossing = "none"`, so every figure
stays a finite, JSON-safe number; `fbsd_report` carries the flag beside the figure.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel, complex_pairs
from hopkinson.analysis.numerics import bracketed_root

DEFAULT_LEVELS = (0.05, 0.10)

# Frequencies examined before the root-finder refines a crossing: a uniform grid plus a
# geometric one (for crossings far below f_max), plus the caller's frequencies of interest
# (pole and zero angles, where narrow peaks and notches sit).
_LINEAR_POINTS = 20_001
_LOG_POINTS = 2_001
_LOG_DECADES = 6


def level_key(level: float) -> str:
    """The dictionary key of a band level: 0.05 → "5", 0.10 → "10" (per cent)."""
    return f"{round(level * 100.0, 6):g}"


@dataclass(frozen=True)
class BandEdge:
    """Where the normalised gain first leaves 1 ± level.

    crossing: "above" (the gain rose past 1 + level), "below" (fell under 1 − level) or
    "none" (it stayed within the band up to f_max: frequency_hz is then f_max itself).
    """

    level: float
    frequency_hz: float
    crossing: str

    @property
    def reached(self) -> bool:
        return self.crossing != "none"

    def to_dict(self) -> dict[str, Any]:
        return {
            "level": self.level,
            "frequency_hz": self.frequency_hz,
            "crossing": self.crossing,
            "within_band_to_limit": not self.reached,
        }


def base_grid(f_max_hz: float) -> np.ndarray:
    """The grid `band_edges` examines on [0, f_max_hz] before the frequencies of interest join it
    (sorted, unique): a caller that finds many models' edges up to one f_max builds it once."""
    return np.unique(np.concatenate([np.linspace(0.0, f_max_hz, _LINEAR_POINTS),
                                     np.geomspace(f_max_hz * 10.0**-_LOG_DECADES, f_max_hz, _LOG_POINTS)]))


def band_edges(
    gain: Callable[[np.ndarray], np.ndarray],
    f_max_hz: float,
    levels: Sequence[float] = DEFAULT_LEVELS,
    frequencies_of_interest_hz: Iterable[float] = (),
    grid: np.ndarray | None = None,
) -> dict[str, BandEdge]:
    """Band edges of a normalised gain function g(f) = |H(f)/H(0)| on [0, f_max_hz].

    `gain` takes an array of frequencies (Hz) and returns the normalised magnitude. The
    first grid point outside 1 ± level brackets the crossing with the point before it;
    brentq then locates it to ~1e-12 relative. Narrow features can only be found if the
    grid samples them: pass their frequencies in `frequencies_of_interest_hz`. `grid`:
    `base_grid(f_max_hz)` when the caller has it already.
    """
    if not f_max_hz > 0:
        raise AnalysisError(f"band edges: f_max must be positive, got {f_max_hz}")
    base = base_grid(f_max_hz) if grid is None else grid
    grid = np.unique(np.concatenate(
        [base, np.asarray([f for f in frequencies_of_interest_hz if 0.0 < f < f_max_hz], dtype=float)]))
    g = np.asarray(gain(grid), dtype=float)
    if not np.all(np.isfinite(g)):
        raise AnalysisError("band edges: the gain is not finite on [0, f_max] (a pole on the unit circle?)")
    edges: dict[str, BandEdge] = {}
    for level in levels:
        if not 0.0 < level < 1.0:
            raise AnalysisError(f"band edges: level must be between 0 and 1, got {level}")
        outside = np.flatnonzero(np.abs(g - 1.0) > level)
        if outside.size == 0:
            edges[level_key(level)] = BandEdge(float(level), float(f_max_hz), "none")
            continue
        i = int(outside[0])
        if i == 0:
            raise AnalysisError("band edges: the gain at DC is not 1; normalise it by H(0) first")
        above = g[i] > 1.0
        target = 1.0 + level if above else 1.0 - level

        def offset(f: float, target: float = target) -> float:
            return float(np.asarray(gain(np.array([f])), dtype=float)[0]) - target

        f_edge = bracketed_root(offset, grid[i - 1], grid[i], 1e-12 * grid[i])
        edges[level_key(level)] = BandEdge(float(level), float(f_edge), "above" if above else "below")
    return edges


def fbsd_from_response(
    frequency_hz: np.ndarray, magnitude_normalised: np.ndarray, levels: Sequence[float] = DEFAULT_LEVELS
) -> dict[str, BandEdge]:
    """Band edges from a sampled normalised magnitude (e.g. a measured response).

    The crossing is interpolated linearly between the two samples that bracket it; the
    band is only as exact as the sampling. frequency_hz must start at or near DC.
    """
    f = np.asarray(frequency_hz, dtype=float)
    m = np.asarray(magnitude_normalised, dtype=float)
    if f.ndim != 1 or f.shape != m.shape or f.size < 2:
        raise AnalysisError("FBSD: frequency and magnitude must be 1-D arrays of the same length (≥ 2)")
    if np.any(np.diff(f) <= 0):
        raise AnalysisError("FBSD: frequencies must be increasing")
    edges: dict[str, BandEdge] = {}
    for level in levels:
        outside = np.flatnonzero(np.abs(m - 1.0) > level)
        if outside.size == 0:
            edges[level_key(level)] = BandEdge(float(level), float(f[-1]), "none")
            continue
        i = int(outside[0])
        if i == 0:
            raise AnalysisError("FBSD: the first magnitude sample is already outside the band; normalise by H(0)")
        above = m[i] > 1.0
        target = 1.0 + level if above else 1.0 - level
        frac = (target - m[i - 1]) / (m[i] - m[i - 1])
        edges[level_key(level)] = BandEdge(
            float(level), float(f[i - 1] + frac * (f[i] - f[i - 1])), "above" if above else "below"
        )
    return edges


def frequency_response(model: DiscreteModel, frequency_hz: np.ndarray) -> np.ndarray:
    """Complex H(e^{j2πfT}) of the model at the given frequencies (Hz).

    The model's input delay (delay_samples) is not included: it changes the phase only,
    and the identified dynamics are what the FBSD and DCM describe.
    """
    f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
    return _polynomial_ratio(model.b, model.a, 2.0 * np.pi * f * model.sample_interval_s)


def _polynomial_ratio(b: np.ndarray, a: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """B(e^{−jω})/A(e^{−jω}) for coefficients in powers of z⁻¹ (what scipy.signal.freqz gives;
    written out so that the analysis does not load scipy.signal, ~0.4 s, for it)."""
    z = np.exp(-1j * np.asarray(omega, dtype=float))
    return np.polyval(np.asarray(b, dtype=float)[::-1], z) / np.polyval(np.asarray(a, dtype=float)[::-1], z)


def nyquist_hz(model: DiscreteModel) -> float:
    """Half the sample rate of the model."""
    return 0.5 / model.sample_interval_s


def pole_zero_frequencies_hz(values: np.ndarray, sample_interval_s: float) -> np.ndarray:
    """The frequencies |arg z|/(2πT) where discrete poles or zeros put peaks and notches."""
    v = np.asarray(values, dtype=complex)
    return np.abs(np.angle(v)) / (2.0 * np.pi * sample_interval_s)


def normalised_gain_function(
    b: np.ndarray, a: np.ndarray, sample_interval_s: float
) -> Callable[[np.ndarray], np.ndarray]:
    """g(f) = |H(f)/H(0)| of a discrete (b, a) in powers of z⁻¹."""
    dc = float(np.sum(b) / np.sum(a)) if np.sum(a) != 0 else np.inf
    if not np.isfinite(dc) or dc == 0.0:
        raise AnalysisError("FBSD: the model has no finite, non-zero DC gain (a pole or zero at z = 1)")
    def gain(frequency_hz: np.ndarray) -> np.ndarray:
        omega = 2.0 * np.pi * np.atleast_1d(np.asarray(frequency_hz, dtype=float)) * sample_interval_s
        return np.abs(_polynomial_ratio(b, a, omega)) / abs(dc)

    return gain


def fbsd_edges(model: DiscreteModel, levels: Sequence[float] = DEFAULT_LEVELS, grid: np.ndarray | None = None
               ) -> dict[str, BandEdge]:
    """The model's band edges (BandEdge per level key), searched up to Nyquist (`grid`:
    `base_grid(nyquist_hz(model))`, when the caller has it)."""
    gain = normalised_gain_function(model.b, model.a, model.sample_interval_s)
    special = pole_zero_frequencies_hz(np.concatenate([model.poles, model.zeros]), model.sample_interval_s)
    return band_edges(gain, nyquist_hz(model), levels, special, grid)


def edge_gradient(model: DiscreteModel, edge: BandEdge) -> tuple[np.ndarray, np.ndarray]:
    """∂f_edge/∂a_i (i = 1…n; a_0 = 1 held) and ∂f_edge/∂b_i (i = 0…m) of a band edge of the
    model's normalised gain g(f) = |H(f)/H(0)|, in Hz per unit coefficient: zeros for an edge
    not reached (it sits at f_max whatever the model).

    Implicit differentiation of g(f_edge; a, b) = 1 ± level: ∂f_edge/∂θ = −(∂ln g/∂θ)/(∂ln g/∂f)
    at the edge, with (z_i = e^{−jωi}, ω = 2πf·T)

        ∂ln g/∂a_i = −Re(z_i/A) + 1/ΣA,   ∂ln g/∂b_i = Re(z_i/B) − 1/ΣB,
        ∂ln g/∂ω = Re(B′/B − A′/A),       A′ = Σ −j·i·a_i·z_i (and B′ so).

    The exact derivative that central differences of the edge approximate (one model's edge
    located once instead of two per coefficient)."""
    a = np.asarray(model.a, dtype=float)
    b = np.asarray(model.b, dtype=float)
    if not edge.reached:
        return np.zeros(a.size - 1), np.zeros(b.size)
    dt = model.sample_interval_s
    omega = 2.0 * np.pi * edge.frequency_hz * dt
    za = np.exp(-1j * omega * np.arange(a.size))
    zb = za[: b.size] if b.size <= a.size else np.exp(-1j * omega * np.arange(b.size))
    big_a, big_b = za @ a, zb @ b
    da = -np.real(za[1:] / big_a) + 1.0 / np.sum(a)
    db = np.real(zb / big_b) - 1.0 / np.sum(b)
    d_omega = np.real((-1j * np.arange(b.size) * zb) @ b / big_b - (-1j * np.arange(a.size) * za) @ a / big_a)
    d_f = d_omega * 2.0 * np.pi * dt  # ∂ln g/∂f
    return -da / d_f, -db / d_f


def fbsd_hz(model: DiscreteModel, levels: Sequence[float] = DEFAULT_LEVELS) -> dict[str, float]:
    """FBSD in Hz per level: {"5": f5, "10": f10} for the default levels.

    An edge never reached below Nyquist is reported as the Nyquist frequency; use
    `fbsd_report` to see which edges were reached and from which side.
    """
    return {k: e.frequency_hz for k, e in fbsd_edges(model, levels).items()}


def fbsd_bounds(edges_hz: dict[str, float], supported_band_hz: tuple[float, float] | None) -> dict[str, dict[str, Any]]:
    """FBSD edges beyond what the shot supports, as bounds: {level: {"lower_bound_hz", "reason"}}.

    Above the band the excitation supports, the model's response is an extrapolation: all the
    shot shows is that the gain stays within the band up to the band's top, so the edge is
    reported as "> that frequency" (the model's own figure stays in fbsd_hz)."""
    if supported_band_hz is None:
        return {}
    top = float(supported_band_hz[1])
    return {
        key: {"lower_bound_hz": top,
              "reason": f"unsupported by the excitation (the pulse supports up to {top / 1e3:.3g} kHz; the model "
                        f"puts the edge at {f / 1e3:.3g} kHz)"}
        for key, f in edges_hz.items() if f > top
    }


def fbsd_report(model: DiscreteModel, levels: Sequence[float] = DEFAULT_LEVELS) -> dict[str, dict[str, Any]]:
    """JSON-safe band edges with the side crossed and whether Nyquist limited them."""
    return {k: e.to_dict() for k, e in fbsd_edges(model, levels).items()}


def response_times_samples(poles: np.ndarray) -> np.ndarray:
    """T'_r of each pole in sample intervals (Eqs. 18–21): 3 / ln(cos θ / α), θ = atan(β/α).

    cos θ / α equals 1/|p| (for α > 0), so T'_r = −3 / ln|p|, which also covers real
    poles (3 / ln(1/p)) and poles with a negative real part. A pole at the origin has
    T'_r = 0; a pole on or outside the unit circle never settles and is an error.
    """
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    mag = np.abs(p)
    if np.any(mag >= 1.0):
        bad = p[np.argmax(mag)]
        raise AnalysisError(f"pole {bad.real:.6g}{bad.imag:+.6g}j is on or outside the unit circle: the model is unstable")
    with np.errstate(divide="ignore"):
        return np.where(mag > 0.0, -3.0 / np.log(np.where(mag > 0.0, mag, 1.0)), 0.0)


def pole_analysis(poles: np.ndarray) -> list[dict[str, Any]]:
    """Table 1 of the paper: per pole its [re, im], response time T'_r and ratio r_i.

    ratio = T'_r(slowest pole) / T'_r; a pole at the origin (T'_r = 0) has ratio None.
    Listed in the order given.
    """
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    if p.size == 0:
        return []
    tr = response_times_samples(p)
    slowest = float(np.max(tr))
    rows = []
    for pole, t in zip(complex_pairs(p), tr, strict=True):
        rows.append(
            {
                "pole": pole,
                "response_time_samples": float(t),
                "ratio": float(slowest / t) if t > 0 else None,
            }
        )
    return rows


def natural_frequency_damping(poles: np.ndarray, sample_interval_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequency (Hz) and damping ratio of each discrete pole, via s = ln(z)/T.

    A negative real pole maps to the Nyquist frequency; a pole at the origin is an error.
    """
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    if np.any(p == 0):
        raise AnalysisError("a pole at z = 0 (a pure delay) has no natural frequency")
    s = np.log(p) / sample_interval_s
    wn = np.abs(s)
    return wn / (2.0 * np.pi), -s.real / wn


def _delay_free_zpk(model: DiscreteModel) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Zeros, poles, gain (positive powers of z, as many zeros as poles) and the delay d.

    H(z) = z^(−d) · k·Π(z − zᵢ)/Π(z − pᵢ). b and a are in powers of z⁻¹: d leading zeros
    of b are the delay; a b shorter than a gives zeros at the origin, a longer one poles.
    """
    b = np.asarray(model.b, dtype=float)
    nz = np.flatnonzero(b)
    if nz.size == 0:
        raise AnalysisError("model: the numerator b is all zeros")
    delay = int(nz[0])
    b = np.trim_zeros(b[delay:], "b")
    zeros = np.roots(b) if b.size > 1 else np.array([], dtype=complex)
    poles = model.poles
    if zeros.size < poles.size:
        zeros = np.concatenate([zeros, np.zeros(poles.size - zeros.size)])
    else:
        poles = np.concatenate([poles, np.zeros(zeros.size - poles.size)])
    return zeros.astype(complex), poles.astype(complex), float(b[0]), delay


def zpk_to_sos(zeros: np.ndarray, poles: np.ndarray, gain: float, delay_samples: int = 0) -> np.ndarray:
    """Second-order sections of z^(−delay)·k·Π(z − zᵢ)/Π(z − pᵢ) (positive powers of z).

    Built by hand around zpk2sos because scipy's zpk2sos (and tf2sos on z⁻¹ coefficients
    with leading zeros) pads missing zeros with zeros at the origin, which silently turns a
    strictly proper filter into one that runs ahead of its input. Here the relative
    degree and any delay become explicit pure-delay sections (b = [0, 0, 1] or [0, 1, 0]).
    """
    z = np.atleast_1d(np.asarray(zeros, dtype=complex))
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    lag = p.size - z.size
    if lag < 0:
        raise AnalysisError(f"{z.size} zeros but only {p.size} poles: the filter would not be causal")
    z = np.concatenate([z, np.zeros(lag, dtype=complex)])
    from scipy import signal

    sos = signal.zpk2sos(z, p, gain) if p.size else np.array([[gain, 0.0, 0.0, 1.0, 0.0, 0.0]])
    delay = lag + int(delay_samples)
    rows = [[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]] * (delay // 2) + [[0.0, 1.0, 0.0, 1.0, 0.0, 0.0]] * (delay % 2)
    return np.vstack([sos, np.array(rows)]) if rows else sos


def model_sos(model: DiscreteModel) -> np.ndarray:
    """Second-order sections of the model (numerically safer than (b, a) at high order)."""
    z, p, k, delay = _delay_free_zpk(model)
    return zpk_to_sos(z, p, k, delay)


def model_output(model: DiscreteModel, u: np.ndarray) -> np.ndarray:
    """The model's response to u from rest, through its second-order sections (well conditioned
    at high order). The input delay (delay_samples) is not included."""
    from scipy import signal

    return signal.sosfilt(model_sos(model), np.asarray(u, dtype=float))


def delayed_model_output(model: DiscreteModel, u: np.ndarray) -> np.ndarray:
    """The model's response to u from rest with its input delay (fractional): what the model
    predicts on the record it was fitted to, computed exactly as analysis.identify computes
    its fit (`simulate_from_rest`), so a report reproduces a shot's own fit to rounding."""
    return simulate_from_rest(model.a, model.b, float(model.delay_samples or 0.0), u)


def simulate_from_rest(a: np.ndarray, b: np.ndarray, delay_samples: float, u: np.ndarray) -> np.ndarray:
    """(B/A)·u(k − τ) from rest, in the frequency domain: the record padded with zeros past the
    slowest pole's decay (to 1e-12, at most four record lengths), the delay and B's length, so the
    circular convolution is the linear one; the fractional delay τ is the linear phase the
    identification fits (the signal taken as zero before its start). NumPy only:
    scipy.signal.lfilter would load scipy.signal (~0.4 s) on the identification's path for this
    alone."""
    from numpy import fft

    from hopkinson.analysis.numerics import next_fast_len

    u = np.asarray(u, dtype=float)
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = u.size
    radius = float(np.max(np.abs(np.roots(a)))) if a.size > 1 else 0.0
    decay = int(min(4 * n, 27.7 / max(-math.log(max(radius, 1e-300)), 1e-12))) if radius > 0 else 0
    size = next_fast_len(n + decay + int(math.ceil(delay_samples)) + b.size)
    omega = 2.0 * np.pi * fft.rfftfreq(size)
    z = np.exp(-1j * omega)
    h = np.polyval(b[::-1], z) / np.polyval(a[::-1], z) * np.exp(-1j * omega * delay_samples)
    return fft.irfft(fft.rfft(u, size) * h, size)[:n]


def to_continuous(model: DiscreteModel) -> tuple[np.ndarray, np.ndarray, float]:
    """Continuous zeros, poles (rad/s) and gain matching the discrete model.

    Method: pole-zero matching, s = ln(z)/T, the inverse of the matched z-transform.
    scipy has no d2c; an inverse bilinear transform would warp every pole's frequency
    (exactly only at one prewarp frequency) while the matched mapping returns the true
    continuous poles whatever the discretisation (ZOH, impulse-invariant, matched), since
    all of them place the poles at exp(sT). Zeros on the negative real axis are the
    sampling zeros a ZOH adds (continuous zeros at infinity) and are dropped, as are
    zeros/poles at the origin (delays). A negative real pole, which has no real
    first-order counterpart, becomes the pair (ln|p| ± jπ)/T. The gain is set so the DC
    gains agree. The input delay is not included.
    """
    T = model.sample_interval_s
    p = model.poles
    if np.any(np.abs(p - 1.0) < 1e-12):
        raise AnalysisError("model has a pole at z = 1 (an integrator): no finite DC gain to match")
    cont_p: list[complex] = []
    for pole in p:
        if abs(pole) == 0.0:
            continue
        if abs(pole.imag) == 0.0 and pole.real < 0:
            sigma = np.log(abs(pole.real)) / T
            cont_p += [complex(sigma, np.pi / T), complex(sigma, -np.pi / T)]
        else:
            cont_p.append(np.log(pole) / T)
    cont_z = [
        np.log(z) / T
        for z in model.zeros
        if abs(z) > 0.0 and not (abs(z.imag) <= 1e-12 * max(1.0, abs(z)) and z.real < 0)
    ]
    poles_s = np.array(cont_p, dtype=complex)
    zeros_s = np.array(cont_z, dtype=complex)
    # DC gain of k·Π(s − z)/Π(s − p) at s = 0 is k·Π(−z)/Π(−p).
    shape_dc = np.prod(-zeros_s) / np.prod(-poles_s)
    if shape_dc == 0:
        raise AnalysisError("model has a zero at z = 1: no DC gain to match")
    gain = float(np.real(model.dc_gain / shape_dc))
    return zeros_s, poles_s, gain


def continuous_tf(model: DiscreteModel) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (num, den) in descending powers of s from `to_continuous`."""
    z, p, k = to_continuous(model)
    from scipy import signal

    num, den = signal.zpk2tf(z, p, k)
    return np.real(num), np.real(den)

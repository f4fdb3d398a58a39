"""Geometric dispersion of a cylindrical bar: the Pochhammer–Chree first longitudinal mode.

For a free solid cylinder of radius a, a longitudinal wave e^{i(kx − ωt)} exists where
(Graff, Wave Motion in Elastic Solids, §8.2)

    (2α/a)(β² + k²)·J₁(αa)J₁(βa) − (β² − k²)²·J₀(αa)J₁(βa) − 4k²αβ·J₁(αa)J₀(βa) = 0,
    α² = ω²/c_L² − k²,  β² = ω²/c_T² − k²,

c_L and c_T the dilatational and shear speeds. The first mode's phase velocity c = ω/k falls
from the bar speed c₀ = √(E/ρ) at long wavelengths (Rayleigh's correction: c/c₀ ≈ 1 − ν²π²(a/Λ)²)
towards the Rayleigh surface-wave speed c_R at short ones: the high frequencies of a pulse fall
behind, so a long bar turns a sharp front into a slower rise followed by a ringing tail.

The root is found once per Poisson's ratio on a grid of the dimensionless frequency f·a/c_T
(SciPy's Bessel functions on complex arguments cover α or β imaginary; Brent's method between
c_R and c₀) and interpolated; a pulse is dispersed over a length L by multiplying its spectrum by
e^{−iωL(1/c(f) − 1/c₀)}, its time kept relative to the front's arrival at c₀.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import optimize, special

from hopkinson.analysis.bar.materials import Material

GRID_POINTS = 240
GRID_TOP = 3.0  # f·a/c_T: beyond, the first mode is at the Rayleigh speed to < 0.1 %


def rayleigh_speed_ratio(poisson_ratio: float) -> float:
    """c_R/c_T: the root of (2 − ξ²)² = 4√(1 − ξ²η²)√(1 − ξ²), η = c_T/c_L, in (0, 1)."""
    nu = poisson_ratio
    eta2 = (1 - 2 * nu) / (2 * (1 - nu))  # (c_T/c_L)²

    def rayleigh(xi: float) -> float:
        x2 = xi * xi
        return (2 - x2) ** 2 - 4 * np.sqrt(1 - x2 * eta2) * np.sqrt(1 - x2)

    return float(optimize.brentq(rayleigh, 0.5, 0.999999))


def _frequency_equation(c_over_ct: float, fa_over_ct: float, poisson_ratio: float) -> float:
    """The Pochhammer–Chree determinant for phase speed c/c_T at frequency f·a/c_T (a = 1,
    c_T = 1): real up to a constant phase, which is removed."""
    nu = poisson_ratio
    cl2 = 2 * (1 - nu) / (1 - 2 * nu)  # (c_L/c_T)²
    w = 2 * np.pi * fa_over_ct
    k = w / c_over_ct
    alpha = np.sqrt(complex(w * w / cl2 - k * k))
    beta = np.sqrt(complex(w * w - k * k))
    j0a, j1a = special.jv(0, alpha), special.jv(1, alpha)
    j0b, j1b = special.jv(0, beta), special.jv(1, beta)
    value = (2 * alpha * (beta**2 + k**2) * j1a * j1b - (beta**2 - k**2) ** 2 * j0a * j1b
             - 4 * k**2 * alpha * beta * j1a * j0b)
    return float(value.real + value.imag)  # one of the two is zero: the other carries the sign


@lru_cache(maxsize=16)
def _table(poisson_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """(f·a/c_T, c/c₀) of the first mode on a grid, for this Poisson's ratio."""
    nu = poisson_ratio
    c0_over_ct = np.sqrt(2 * (1 + nu))  # c₀/c_T = √(E/μ)
    cr = rayleigh_speed_ratio(nu)
    grid = np.linspace(0.0, GRID_TOP, GRID_POINTS)
    ratio = np.ones(GRID_POINTS)
    upper = c0_over_ct * (1 - 1e-12)
    for i, x in enumerate(grid[1:], start=1):
        lower = cr * (1 + 1e-9)
        # scan down from the bar speed for the first sign change: the first mode is the fastest
        root = None
        for bottom, count in ((max(lower, 0.9 * upper), 8), (lower, 60)):  # near the last root first
            trial = np.linspace(upper, bottom, count)
            values = [_frequency_equation(c, x, nu) for c in trial]
            for c1, c2, v1, v2 in zip(trial[:-1], trial[1:], values[:-1], values[1:], strict=True):
                if v1 == 0.0:
                    root = c1
                    break
                if v1 * v2 < 0:
                    root = optimize.brentq(_frequency_equation, c2, c1, args=(x, nu), xtol=1e-12)
                    break
            if root is not None:
                break
        ratio[i] = (root if root is not None else cr) / c0_over_ct
        upper = (root if root is not None else cr) * (1 + 1e-6)  # the mode's speed falls with frequency
    return grid, ratio


def phase_velocity_m_s(frequency_hz: np.ndarray, radius_m: float, props: Material) -> np.ndarray:
    """The first mode's phase velocity at each frequency (c₀ at 0 Hz, → c_R above the table)."""
    grid, ratio = _table(round(props.poisson_ratio, 6))
    x = np.abs(np.asarray(frequency_hz, dtype=float)) * radius_m / props.shear_speed_m_s
    cr = rayleigh_speed_ratio(props.poisson_ratio) * props.shear_speed_m_s / props.bar_speed_m_s
    return props.bar_speed_m_s * np.interp(x, grid, ratio, right=cr)


def disperse(signal: np.ndarray, sample_interval_s: float, length_m: float, radius_m: float,
             props: Material) -> np.ndarray:
    """`signal` (a wave at one cross-section, any quantity) as it arrives `length_m` further along
    the bar, its time origin moved with the front at c₀; the same number of samples (the
    record is padded so no delayed part wraps round)."""
    x = np.asarray(signal, dtype=float)
    n = x.size
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spectrum = np.fft.rfft(x, size)
    f = np.fft.rfftfreq(size, sample_interval_s)
    c = phase_velocity_m_s(f, radius_m, props)
    lag = length_m * (1.0 / c - 1.0 / props.bar_speed_m_s)
    return np.fft.irfft(spectrum * np.exp(-2j * np.pi * f * lag), size)[:n]

"""Shock pulses the Hopkinson bar imparts to the calibrated object (the simulated truth).

Pure NumPy: used by the simulated rig and by tests as the known excitation.
All functions take a time axis in seconds and return acceleration in m/s².
"""

from __future__ import annotations

import numpy as np

G_M_S2 = 9.80665  # standard gravity, m/s²


def half_sine_m_s2(time_s: np.ndarray, width_s: float, peak_m_s2: float, start_s: float = 0.0) -> np.ndarray:
    """Half-sine acceleration pulse of full width `width_s` (zero to zero) starting at `start_s`."""
    t = np.asarray(time_s, dtype=float) - start_s
    inside = (t >= 0.0) & (t < width_s)
    return np.where(inside, peak_m_s2 * np.sin(np.pi * np.clip(t, 0.0, width_s) / width_s), 0.0)


def gaussian_velocity_m_s2(time_s: np.ndarray, sigma_s: float, peak_m_s2: float, centre_s: float) -> np.ndarray:
    """Acceleration of a Gaussian velocity *step* (erf velocity): a Gaussian pulse.

    The object's velocity rises smoothly as an error function; its acceleration is a
    Gaussian of standard deviation `sigma_s` and height `peak_m_s2` centred at `centre_s`.
    """
    t = np.asarray(time_s, dtype=float) - centre_s
    return peak_m_s2 * np.exp(-0.5 * (t / sigma_s) ** 2)


def dipole_m_s2(time_s: np.ndarray, sigma_s: float, peak_m_s2: float, centre_s: float) -> np.ndarray:
    """Acceleration of a Gaussian velocity *pulse* (the object goes and comes back): a dipole.

    The derivative of a Gaussian, scaled so its largest value is `peak_m_s2`.
    """
    t = np.asarray(time_s, dtype=float) - centre_s
    shape = -(t / sigma_s) * np.exp(0.5 - 0.5 * (t / sigma_s) ** 2)
    return peak_m_s2 * shape


def velocity_m_s(acceleration_m_s2: np.ndarray, sample_interval_s: float) -> np.ndarray:
    """Velocity by trapezoidal integration of acceleration, starting from rest."""
    a = np.asarray(acceleration_m_s2, dtype=float)
    v = np.empty_like(a)
    v[0] = 0.0
    np.cumsum(0.5 * (a[1:] + a[:-1]) * sample_interval_s, out=v[1:])
    return v


def bipolar_m_s2(time_s: np.ndarray, width_s: float, peak_m_s2: float, start_s: float = 0.0,
                 ratio: float = 0.6, second_width_s: float | None = None) -> np.ndarray:
    """A bipolar pulse: a half-sine of `peak_m_s2` and base width `width_s`, then at once a
    negative half-sine of `ratio`·peak and base width `second_width_s` (default `width_s`).

    The object gains peak·width·2/π of velocity and gives back ratio·peak·second_width·2/π; with
    ratio·second_width < width it keeps moving forwards (one PM channel can follow it).
    """
    second = width_s if second_width_s is None else second_width_s
    first = half_sine_m_s2(time_s, width_s, peak_m_s2, start_s)
    return first - half_sine_m_s2(time_s, second, ratio * peak_m_s2, start_s + width_s)


def bipolar_velocity_m_s(time_s: np.ndarray, width_s: float, peak_m_s2: float, start_s: float = 0.0,
                         ratio: float = 0.6, second_width_s: float | None = None) -> np.ndarray:
    """Exact integral of `bipolar_m_s2` from rest: the object's velocity (m/s)."""
    second = width_s if second_width_s is None else second_width_s

    def lobe(width: float, peak: float, start: float) -> np.ndarray:
        t = np.clip(np.asarray(time_s, dtype=float) - start, 0.0, width)
        return peak * width / np.pi * (1.0 - np.cos(np.pi * t / width))

    return lobe(width_s, peak_m_s2, start_s) - lobe(second, ratio * peak_m_s2, start_s + width_s)

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

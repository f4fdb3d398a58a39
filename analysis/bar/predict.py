"""A shot predicted from the rig's physics: projectile speed from the reservoir pressure
(geometry.Launcher), the force wave of the impact (lattice.impact_force), its dispersion along
the bar (dispersion.disperse), and the calibrated object's acceleration and flight
(lattice.object_motion: flying off a separating mount, or following the bar's end on a bonded
one). With a rigid or linear contact at the impact face everything is linear in the
projectile's speed (the contacts only open and close on the sign of a force), so one prediction
per projectile at 1 m/s serves every pressure; a stiffening contact (geometry: exponent > 1) gives
a shorter pulse at a higher speed, so each speed is computed (and cached).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import optimize

from hopkinson.analysis.bar.dispersion import disperse
from hopkinson.analysis.bar.geometry import REFERENCE_PRESSURE_BAR, BarRig
from hopkinson.analysis.bar.lattice import impact_force, object_motion

DEFAULT_SAMPLE_INTERVAL_S = 1e-7
DEFAULT_DURATION_S = 2e-3
LEAD_S = 50e-6  # the record starts this long before the front's arrival at c₀


@dataclass(frozen=True)
class ShotPrediction:
    """The calibrated object's acceleration for one projectile at one speed (t = 0: LEAD_S before
    the non-dispersed front's arrival at the bar's far end)."""

    projectile: int
    speed_m_s: float
    sample_interval_s: float
    acceleration_m_s2: np.ndarray
    velocity_m_s: np.ndarray
    incident_stress_pa: np.ndarray  # the stress wave arriving at the far end (dispersed)
    separation_s: float | None
    contact_s: float  # how long the projectile pushed on the bar

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.acceleration_m_s2.size) * self.sample_interval_s

    @property
    def peak_m_s2(self) -> float:
        return float(np.max(self.acceleration_m_s2))

    @property
    def delta_v_m_s(self) -> float:
        """The object's speed when it left the bar (a bonded object's at the record's end: ~0)."""
        return float(self.velocity_m_s[-1])

    @property
    def peak_velocity_m_s(self) -> float:
        """The largest speed the object reaches: the velocity change of the pulse's positive lobe
        (on a separating mount its speed when it left)."""
        return float(np.max(self.velocity_m_s))

    @property
    def equivalent_width_s(self) -> float:
        """δ of the half-sine with the same peak and velocity change over its positive lobe:
        π·Δv/(2·peak) (the paper's pulse width δ for a half-sine)."""
        return math.pi * self.peak_velocity_m_s / (2.0 * self.peak_m_s2) if self.peak_m_s2 > 0 else math.nan

    @property
    def width_10_s(self) -> float:
        """Duration above 10 % of the peak (first to last crossing)."""
        above = np.flatnonzero(self.acceleration_m_s2 >= 0.1 * self.peak_m_s2)
        return float((above[-1] - above[0]) * self.sample_interval_s) if above.size else 0.0

    def scaled(self, speed_m_s: float) -> ShotPrediction:
        """The same shot at another projectile speed (linear elasticity and a linear contact)."""
        k = speed_m_s / self.speed_m_s
        return ShotPrediction(self.projectile, speed_m_s, self.sample_interval_s, self.acceleration_m_s2 * k,
                              self.velocity_m_s * k, self.incident_stress_pa * k, self.separation_s, self.contact_s)


def predict_shot(rig: BarRig, projectile: int, *, speed_m_s: float | None = None, pressure_bar: float | None = None,
                 sample_interval_s: float = DEFAULT_SAMPLE_INTERVAL_S, duration_s: float = DEFAULT_DURATION_S,
                 dispersion: bool = True) -> ShotPrediction:
    """The object's acceleration for `projectile` fired at `speed_m_s` or from `pressure_bar`."""
    if (speed_m_s is None) == (pressure_bar is None):
        raise ValueError("give the projectile's speed or the reservoir pressure, not both")
    speed = speed_m_s if speed_m_s is not None else rig.launcher.speed_m_s(rig.projectile(projectile), pressure_bar)
    if rig.projectile(projectile).linear:
        return _shot(rig, projectile, 1.0, float(sample_interval_s), float(duration_s), bool(dispersion)).scaled(
            float(speed))
    return _shot(rig, projectile, float(speed), float(sample_interval_s), float(duration_s), bool(dispersion))


def speed_for_peak(rig: BarRig, projectile: int, peak_m_s2: float) -> float:
    """The projectile's speed that gives the object `peak_m_s2`: the linear scaling for a linear
    contact; for a stiffening one, the secant method (scipy.optimize.newton without a derivative)
    on log peak against log speed, nearly a straight line, so a few predictions."""
    if not peak_m_s2 > 0:
        raise ValueError(f"the peak must be positive, got {peak_m_s2:g} m/s²")
    speed = rig.launcher.speed_m_s(rig.projectile(projectile), REFERENCE_PRESSURE_BAR)
    peak = predict_shot(rig, projectile, speed_m_s=speed).peak_m_s2
    first_guess = math.log(speed * peak_m_s2 / peak)  # as if the peak were linear in the speed
    if rig.projectile(projectile).linear:
        return math.exp(first_guess)

    def log_excess(log_speed: float) -> float:
        got = predict_shot(rig, projectile, speed_m_s=math.exp(log_speed)).peak_m_s2
        return math.log(got / peak_m_s2) if got > 0 else -math.inf

    failed = ValueError(f"the bar model finds no speed of projectile No. {projectile} that gives {peak_m_s2:g} m/s²")
    try:
        log_speed, result = optimize.newton(log_excess, math.log(speed), x1=first_guess, tol=1e-9, maxiter=40,
                                            full_output=True, disp=False)
    except (ArithmeticError, RuntimeError, ValueError):
        raise failed from None
    if not (result.converged and math.isfinite(log_speed)):
        raise failed
    return math.exp(log_speed)


@lru_cache(maxsize=64)
def _shot(rig: BarRig, number: int, speed_m_s: float, dt: float, duration_s: float, dispersion: bool) -> ShotPrediction:
    projectile = rig.projectile(number)
    spacer = rig.spacer if projectile.uses_spacer else None
    impact = impact_force(list(projectile.segments), spacer, rig.bar, speed_m_s, dt, max_duration_s=duration_s,
                          contact_stiffness_n_m=projectile.contact_stiffness_n_m,
                          contact_exponent=projectile.contact_exponent)
    n = int(round(duration_s / dt))
    lead = int(round(LEAD_S / dt))  # room for the dispersed front's precursor (it runs ahead of c₀)
    wave = np.zeros(n)
    wave[lead: min(n, lead + impact.force_n.size)] = impact.force_n[: n - lead]
    if dispersion:
        wave = disperse(wave, dt, rig.bar.length_m, rig.bar.diameter_m / 2.0, rig.bar.props)
    motion = object_motion(wave, rig.bar, rig.base, rig.sensor_mass_kg, dt, bonded=rig.mount == "bonded")
    accel = np.zeros(n)
    accel[: motion.acceleration_m_s2.size] = motion.acceleration_m_s2[:n]
    velocity = np.cumsum(accel) * dt
    return ShotPrediction(number, speed_m_s, dt, accel, velocity, wave / rig.bar.area_m2, motion.separation_s,
                          impact.contact_s)

"""Shot planning: which projectile and pressure give a target peak acceleration, and whether
the pulse will excite the sensor (bar model: analysis.bar.predict).

For each projectile the speed that gives the target peak is found (predict.speed_for_peak: a
scaling for a linear contact, a few predictions for a stiffening one), the launcher gives the
pressure for it, and the pulse at that speed gives its width and its spectrum's bands:
  - the −3 dB frequency: where |A(f)| of the acceleration pulse, above its maximum, first falls
    below 1/√2 of it (the maximum is at DC for a separating mount's unipolar pulse);
  - the supported band's top: the identification's own rule (analysis.excitation.supported_band:
    the pulse window's stretches within 40 dB of the spectrum's maximum, across the pulse's
    narrow nulls), the reference's noise left out (a prediction has none: the analysis of a
    shot can stop lower where the noise rises above a weak sidelobe);
  - the paper's rule δ ≤ 1.06/f_n (Eq. 36; PAPER-NOTES: it does not follow from its Eqs.
    33–35, so both it and the supported band are given), with δ the equivalent half-sine width.
The projectile to load: among those within the rig's pressure limits (and meeting the rule when
a sensor's f_n is named, if any does), the one with the widest supported band.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from hopkinson.analysis.bar.geometry import G_M_S2, BarRig, Projectile
from hopkinson.analysis.bar.predict import ShotPrediction, predict_shot, speed_for_peak
from hopkinson.analysis.excitation import supported_band

PAPER_RULE = 1.06  # δ·f_n at most (the paper's Eq. 36)
SUPPORT_DB = -40.0


@dataclass(frozen=True)
class ProjectileOption:
    """What one projectile would do at the pressure that gives the target peak."""

    projectile: int
    description: str
    pressure_bar: float
    speed_m_s: float
    peak_m_s2: float
    width_s: float  # equivalent half-sine width δ = π·Δv/(2·peak) (Δv of the positive lobe)
    width_10_s: float
    minus_3db_hz: float
    supported_band_hz: float
    reachable: bool
    why_not: str  # "" when reachable
    paper_rule_holds: bool | None  # δ ≤ 1.06/f_n for the named sensor (None: no sensor named)

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class ShotPlan:
    target_peak_m_s2: float
    sensor_fn_hz: float | None
    options: tuple[ProjectileOption, ...]
    chosen: int | None
    reason: str

    def to_dict(self) -> dict[str, object]:
        return {"target_peak_m_s2": self.target_peak_m_s2, "target_peak_g": self.target_peak_m_s2 / G_M_S2,
                "sensor_fn_hz": self.sensor_fn_hz, "chosen_projectile": self.chosen, "reason": self.reason,
                "projectiles": [o.to_dict() for o in self.options]}


def spectrum_bands_hz(prediction: ShotPrediction) -> tuple[float, float]:
    """(−3 dB frequency, supported band's top) of the acceleration pulse's amplitude spectrum,
    both relative to its maximum and above it: at DC for a pulse that never turns negative (a
    separating mount), at a few kHz for a bonded mount's bipolar pulse (no net velocity change,
    so nothing at DC). The top by the analysis' own rule (analysis.excitation.supported_band)."""
    a = prediction.acceleration_m_s2
    size = 1 << int(np.ceil(np.log2(8 * a.size)))
    spectrum = np.abs(np.fft.rfft(a, size))
    f = np.fft.rfftfreq(size, prediction.sample_interval_s)
    top = int(np.argmax(spectrum))
    rel = spectrum[top:] / spectrum[top]
    below_3 = np.flatnonzero(rel < 1 / math.sqrt(2))
    support = supported_band(a, prediction.sample_interval_s, floor=10 ** (SUPPORT_DB / 20))
    return float(f[top + below_3[0]]) if below_3.size else float(f[-1]), support.top_hz


def _peak_g_at(rig: BarRig, projectile: Projectile, pressure_bar: float) -> str:
    """The peak `projectile` gives from `pressure_bar`, in g."""
    return f"{predict_shot(rig, projectile.number, pressure_bar=pressure_bar).peak_m_s2 / G_M_S2:,.0f} g"


def plan_shot(rig: BarRig, target_peak_m_s2: float, *, sensor_fn_hz: float | None = None,
              min_pressure_bar: float = 0.0, max_pressure_bar: float = math.inf) -> ShotPlan:
    """Every projectile's pressure, pulse and bands for the target peak, and which to load."""
    if not target_peak_m_s2 > 0:
        raise ValueError(f"the target peak must be positive, got {target_peak_m_s2:g} m/s²")
    if sensor_fn_hz is not None and not sensor_fn_hz > 0:
        raise ValueError(f"the sensor's natural frequency must be positive, got {sensor_fn_hz:g} Hz")
    options = []
    for projectile in rig.projectiles:
        speed = speed_for_peak(rig, projectile.number, target_peak_m_s2)
        pressure = rig.launcher.pressure_bar(projectile, speed)
        shot = predict_shot(rig, projectile.number, speed_m_s=speed)
        low, top = spectrum_bands_hz(shot)
        why = ""
        if pressure > max_pressure_bar:
            why = (f"needs {pressure:.3g} bar, above the rig's maximum {max_pressure_bar:g} bar "
                   f"(at most {_peak_g_at(rig, projectile, max_pressure_bar)})")
        elif pressure < min_pressure_bar:
            why = (f"needs {pressure:.3g} bar, below the rig's minimum {min_pressure_bar:g} bar "
                   f"(at least {_peak_g_at(rig, projectile, min_pressure_bar)})")
        rule = None if sensor_fn_hz is None else bool(shot.equivalent_width_s <= PAPER_RULE / sensor_fn_hz)
        options.append(ProjectileOption(projectile.number, projectile.description, pressure, speed, shot.peak_m_s2,
                                        shot.equivalent_width_s, shot.width_10_s, low, top, not why, why, rule))
    reachable = [o for o in options if o.reachable]
    if not reachable:
        return ShotPlan(target_peak_m_s2, sensor_fn_hz, tuple(options), None,
                        "no projectile reaches the target within the rig's pressure limits: "
                        + "; ".join(f"No. {o.projectile} {o.why_not}" for o in options))
    exciting = [o for o in reachable if o.paper_rule_holds] if sensor_fn_hz is not None else reachable
    pool = exciting or reachable
    best = max(pool, key=lambda o: (o.supported_band_hz, -o.pressure_bar))
    reason = f"the widest supported band ({best.supported_band_hz / 1e3:.1f} kHz) within the pressure limits"
    if sensor_fn_hz is not None:
        reason += (f", and δ = {best.width_s * 1e6:.1f} µs ≤ 1.06/f_n = {PAPER_RULE / sensor_fn_hz * 1e6:.1f} µs"
                   if exciting else
                   f"; no reachable projectile meets δ ≤ 1.06/f_n = {PAPER_RULE / sensor_fn_hz * 1e6:.1f} µs: "
                   "the resonance will not be excited")
    return ShotPlan(target_peak_m_s2, sensor_fn_hz, tuple(options), best.projectile, reason)

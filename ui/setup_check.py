"""What the set-up will do, before it is armed: the bar model's shot for the projectile and the
pressure actually set (analysis.bar.predict_shot, the rig's `[bar]`, the same model as the
planner and the level control), compared with the target and the sensor's range.

`predict_setup` gives the predicted peak (g and km/s²), the pulse width and the band the pulse
supports; `SetupPrediction.problems()` says, in one line each, what would make the shot miss its
target by more than the level tolerance (the verdict's: analysis.verdict.LEVEL_TOLERANCE_REL) or
exceed the sensor's range. The panel shows the prediction under the pressure, asks before ARM
when there is a problem, and states the prediction in the FIRE confirmation. Pure (no Qt).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

from hopkinson.analysis.sensitivity_units import G_M_S2
from hopkinson.analysis.verdict import LEVEL_TOLERANCE_REL

if TYPE_CHECKING:
    from hopkinson.analysis.bar import BarRig


@dataclass(frozen=True)
class SetupPrediction:
    """The bar model's shot for a set-up, and what it is compared with (None: not named)."""

    projectile: int
    pressure_bar: float
    peak_m_s2: float
    width_10_s: float  # pulse width at 10 % of the peak (ISO 16063-22), as the analysis measures it
    band_hz: float  # top of the band the pulse supports (−40 dB of its spectrum)
    target_m_s2: float | None = None
    range_m_s2: float | None = None
    level_tolerance_rel: float = LEVEL_TOLERANCE_REL

    @property
    def off_target_rel(self) -> float | None:
        """Predicted peak ÷ target − 1 (None without a target)."""
        return None if not self.target_m_s2 else self.peak_m_s2 / self.target_m_s2 - 1.0

    def peak_text(self) -> str:
        """'50 000 g (490 km/s²)'."""
        return f"{_g(self.peak_m_s2)} g ({self.peak_m_s2 / 1e3:,.0f} km/s²)".replace(",", "\u00a0")

    def summary(self) -> str:
        """'No. 3 at 2.00 bar → 50 000 g (490 km/s²), pulse 41 µs, band to 100 kHz'."""
        return (f"No. {self.projectile} at {self.pressure_bar:.2f} bar → {self.peak_text()}, "
                f"pulse {self.width_10_s * 1e6:.0f} µs, band to {self.band_hz / 1e3:.0f} kHz")

    def target_text(self) -> str:
        """'+1.2 % from the 50 000 g target' ("" without a target)."""
        off = self.off_target_rel
        if off is None or self.target_m_s2 is None:
            return ""
        return f"{100 * off:+.1f} % from the {_g(self.target_m_s2)} g target".replace("-", "−")

    def problems(self) -> list[str]:
        """What to ask about before ARM (module docstring); empty when nothing."""
        out = []
        off = self.off_target_rel
        if off is not None and self.target_m_s2 is not None and abs(off) > self.level_tolerance_rel:
            side = "above" if off > 0 else "below"
            out.append(f"the predicted peak {self.peak_text()} is {abs(100 * off):.0f} % {side} the target "
                       f"{_g(self.target_m_s2)} g (tolerance ±{100 * self.level_tolerance_rel:g} %)")
        if self.range_m_s2 and self.peak_m_s2 > self.range_m_s2:
            out.append(f"the predicted peak {self.peak_text()} exceeds the sensor's range {_g(self.range_m_s2)} g")
        return out


def predict_setup(rig: BarRig, projectile: int, pressure_bar: float, target_m_s2: float | None = None,
                  range_m_s2: float | None = None,
                  level_tolerance_rel: float = LEVEL_TOLERANCE_REL) -> SetupPrediction:
    """The bar model's shot for the set-up (module docstring); ValueError when the model cannot
    predict it (a projectile the rig's [bar] does not describe)."""
    peak, width, band = _predict(rig, projectile, round(float(pressure_bar), 4))
    return SetupPrediction(projectile, float(pressure_bar), peak, width, band, target_m_s2 or None,
                           range_m_s2 or None, level_tolerance_rel)


@lru_cache(maxsize=256)
def _predict(rig: BarRig, projectile: int, pressure_bar: float) -> tuple[float, float, float]:
    from hopkinson.analysis.bar.planning import spectrum_bands_hz
    from hopkinson.analysis.bar.predict import predict_shot

    shot = predict_shot(rig, projectile, pressure_bar=pressure_bar)
    return float(shot.peak_m_s2), float(shot.width_10_s), float(spectrum_bands_hz(shot)[1])


def _g(value_m_s2: float) -> str:
    return f"{value_m_s2 / G_M_S2:,.0f}".replace(",", "\u00a0")


def fire_question(what: str, prediction: SetupPrediction | None) -> str:
    """FIRE's confirmation: `what` is armed, the bar model's prediction for it and its problems."""
    p = prediction
    predicted = ("" if p is None else
                 f"\n\nPredicted peak {p.peak_text()}, pulse width {p.width_10_s * 1e6:.0f} µs, "
                 f"band to {p.band_hz / 1e3:.0f} kHz" + (f" ({p.target_text()})" if p.target_m_s2 else ""))
    warning = "".join(f"\n⚠ {problem}" for problem in (p.problems() if p is not None else []))
    return f"FIRE the armed shot now?\n\n{what}{predicted}{warning}\n\nEvery interlock holds. Make sure nobody is at the bar."

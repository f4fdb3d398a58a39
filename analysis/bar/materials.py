"""Materials of a Hopkinson bar rig: density, Young's modulus, Poisson's ratio, and the wave
speeds and impedance that follow from them.

Values are handbook room-temperature values (ASM Handbook vol. 2 for Ti-6Al-4V and 7075-T6;
EN 10083-2 / MatWeb for C45; Ultramid/PA6 datasheets for nylon, whose dynamic modulus at
impact strain rates is taken, ~1.5× its static one). A lab's own material is added to
`MATERIALS` or named in `[bar]` with its three numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """An isotropic linear-elastic material."""

    name: str
    density_kg_m3: float
    youngs_modulus_pa: float
    poisson_ratio: float

    def __post_init__(self) -> None:
        if not (self.density_kg_m3 > 0 and self.youngs_modulus_pa > 0 and 0.0 <= self.poisson_ratio < 0.5):
            raise ValueError(f"material {self.name}: density and Young's modulus must be positive and Poisson's "
                             f"ratio in [0, 0.5), got {self.density_kg_m3}, {self.youngs_modulus_pa}, "
                             f"{self.poisson_ratio}")

    @property
    def bar_speed_m_s(self) -> float:
        """c₀ = √(E/ρ): the long-wavelength speed of a longitudinal wave in a thin bar."""
        return math.sqrt(self.youngs_modulus_pa / self.density_kg_m3)

    @property
    def shear_speed_m_s(self) -> float:
        """c_T = √(μ/ρ), μ = E/(2(1 + ν))."""
        return math.sqrt(self.youngs_modulus_pa / (2.0 * (1.0 + self.poisson_ratio) * self.density_kg_m3))

    @property
    def dilatational_speed_m_s(self) -> float:
        """c_L = √((λ + 2μ)/ρ) = √(E(1 − ν)/((1 + ν)(1 − 2ν)ρ))."""
        nu = self.poisson_ratio
        return math.sqrt(self.youngs_modulus_pa * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * self.density_kg_m3))

    def impedance_kg_s(self, area_m2: float) -> float:
        """Mechanical impedance Z = ρ·c₀·A (force per unit particle velocity)."""
        return self.density_kg_m3 * self.bar_speed_m_s * area_m2


MATERIALS: dict[str, Material] = {m.name: m for m in (
    Material("C45", 7850.0, 210e9, 0.29),            # unalloyed medium-carbon steel (the projectiles)
    Material("Ti-6Al-4V", 4430.0, 113.8e9, 0.342),   # titanium alloy (the bar and the raster base)
    Material("PA6", 1140.0, 4.2e9, 0.39),            # nylon 6 (projectile No. 3's tail), dynamic modulus
    Material("Al-7075", 2810.0, 71.7e9, 0.33),       # aluminium alloy (the spacer)
)}


def material(name: str) -> Material:
    """The material of that name; ValueError naming the known ones otherwise."""
    try:
        return MATERIALS[name]
    except KeyError:
        raise ValueError(f"unknown material {name!r} (known: {', '.join(sorted(MATERIALS))})") from None

"""The rig's geometry: projectiles, the spacer, the bar, the raster base with the sensor, and
the launcher that turns reservoir pressure into projectile speed.

Defaults are the rig of the paper (Yang et al., §3–4): a Ti-6Al-4V bar Ø16 mm × 1600 mm, an
aluminium spacer at its incident end (left out with projectile No. 3), a raster base of the
bar's material carrying the accelerometer, and the three projectiles of its Fig. 4: No. 1 and
No. 2 of C45 steel with shaped tips, No. 3 a C45 cushion Δ = 3 mm on a nylon tail. The paper
gives no dimensions for the tips, the tails or the base: those here are assumptions; a lab
states its own in config's `[bar]`. A shaped tip (or any compliance at the impact face) is a
contact spring between the projectile and the bar: F = k·δ₁·(δ/δ₁)^p for a compression δ, with
k its secant stiffness at δ₁ = 1 mm (`Projectile.contact_stiffness_n_m`) and p its exponent
(`contact_exponent`): 1 a linear spring, 3/2 a contact that stiffens as it grows, as Hertz's
does (a rounded tip, a seat of asperities, a soft pulse shaper). A stiffening contact starts and
ends the pulse smoothly (the force's slope is zero where δ is), as real records do, and makes
the pulse shorter as the projectile is faster.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from hopkinson.analysis.bar.materials import Material, material

G_M_S2 = 9.80665
CONTACT_REFERENCE_M = 1e-3  # δ₁: a contact's stiffness is its secant stiffness at this compression
HERTZ_EXPONENT = 1.5
REFERENCE_PRESSURE_BAR = 2.0  # where the paper's projectiles give their stated pulse widths (No. 3: 50 000 g)


@dataclass(frozen=True)
class Segment:
    """A uniform piece of a rod: its material, length and diameter."""

    material: str
    length_m: float
    diameter_m: float

    def __post_init__(self) -> None:
        material(self.material)  # a known material
        if not (self.length_m > 0 and self.diameter_m > 0):
            raise ValueError(f"a segment's length and diameter must be positive, got {self.length_m}, "
                             f"{self.diameter_m}")

    @property
    def props(self) -> Material:
        return material(self.material)

    @property
    def area_m2(self) -> float:
        return math.pi * self.diameter_m**2 / 4.0

    @property
    def mass_kg(self) -> float:
        return self.props.density_kg_m3 * self.area_m2 * self.length_m

    @property
    def impedance_kg_s(self) -> float:
        return self.props.impedance_kg_s(self.area_m2)


@dataclass(frozen=True)
class Projectile:
    """A projectile, its segments listed from the impact face backwards."""

    number: int
    description: str
    segments: tuple[Segment, ...]
    uses_spacer: bool = True  # the spacer is left on the bar for this projectile
    contact_stiffness_n_m: float | None = None  # the impact face's contact spring at 1 mm (None: flat and rigid)
    contact_exponent: float = 1.0  # p of F = k·δ₁·(δ/δ₁)^p: 1 linear, 1.5 Hertz's

    def __post_init__(self) -> None:
        if not 1.0 <= self.contact_exponent <= 3.0:
            raise ValueError(f"projectile No. {self.number}: the contact's exponent must lie in 1-3, "
                             f"got {self.contact_exponent}")

    @property
    def linear(self) -> bool:
        """Whether the impact is linear in the speed (a rigid or linear contact): one prediction
        at one speed then serves every speed by scaling."""
        return self.contact_stiffness_n_m is None or self.contact_exponent == 1.0

    @property
    def mass_kg(self) -> float:
        return sum(s.mass_kg for s in self.segments)

    @property
    def rear_area_m2(self) -> float:
        """The area the gas pushes on (the largest section)."""
        return max(s.area_m2 for s in self.segments)


@dataclass(frozen=True)
class Launcher:
    """Gas gun: the reservoir's gauge pressure p acts on the projectile's rear over the barrel,
    a fraction `efficiency` of that work becoming kinetic energy (valve losses, leakage past
    the projectile, the gas's expansion): ½·m·v² = η·p·A·L, so v = √(2ηpAL/m). The paper gives
    no launcher: the defaults put 50 000 g at 2 bar with projectile No. 3, the level the
    earlier simulator gave."""

    barrel_length_m: float = 1.5
    efficiency: float = 0.348

    def __post_init__(self) -> None:
        if not (self.barrel_length_m > 0 and 0 < self.efficiency <= 1):
            raise ValueError(f"launcher: barrel length > 0 and 0 < efficiency ≤ 1, got {self.barrel_length_m}, "
                             f"{self.efficiency}")

    def speed_m_s(self, projectile: Projectile, pressure_bar: float) -> float:
        """The projectile's speed at the bar for a reservoir gauge pressure."""
        work = self.efficiency * max(pressure_bar, 0.0) * 1e5 * projectile.rear_area_m2 * self.barrel_length_m
        return math.sqrt(2.0 * work / projectile.mass_kg)

    def pressure_bar(self, projectile: Projectile, speed_m_s: float) -> float:
        """The gauge pressure that gives `speed_m_s` (the inverse of `speed_m_s`)."""
        return projectile.mass_kg * speed_m_s**2 / (2.0 * self.efficiency * projectile.rear_area_m2
                                                     * self.barrel_length_m) / 1e5


def _paper_projectiles() -> tuple[Projectile, ...]:
    # The contact springs are the one thing fitted here: with flat rigid faces the 1-D physics
    # gives No. 3 a pulse of ~7 µs (its cushion's round trip, spread by the bar's dispersion),
    # not the 38.6 µs the paper measured; a contact compliance (a shaped tip, the faces'
    # asperities, the cushion's seat on its tail) is what the paper does not describe. Each
    # stiffens as Hertz's contact does (exponent 3/2: a linear spring would start and stop the
    # force with a kink, which a bonded object's acceleration shows as a step, and the spectrum as
    # sidelobes ~20 dB above a real record's). Each stiffness is set so the pulse (equivalent
    # half-sine width) from REFERENCE_PRESSURE_BAR is the paper's 38.6 µs for No. 3 and the older
    # simulator's 75 and 120 µs for No. 2 and No. 1 (the paper does not give the pressure).
    steel, nylon = "C45", "PA6"
    return (
        Projectile(1, "C45 steel, rounded tip", (Segment(steel, 0.060, 0.016),), contact_stiffness_n_m=1.33e7,
                   contact_exponent=HERTZ_EXPONENT),
        Projectile(2, "C45 steel, blunt conical tip", (Segment(steel, 0.040, 0.016),), contact_stiffness_n_m=2.467e7,
                   contact_exponent=HERTZ_EXPONENT),
        Projectile(3, "C45 steel cushion Δ = 3 mm on a nylon tail",
                   (Segment(steel, 0.003, 0.016), Segment(nylon, 0.030, 0.016)), uses_spacer=False,
                   contact_stiffness_n_m=1.599e7, contact_exponent=HERTZ_EXPONENT),
    )


# How the calibrated object sits on the bar's end: "separating" (the paper's raster base, held
# by compression only, which flies off when the reflected wave would pull: a unipolar pulse,
# Eqs. 27–30) or "bonded" (screwed or glued to the end face, as PTB's shock calibration mounts
# its sensor: it follows the bar through the whole wave, a bipolar pulse with deep spectral nulls).
MOUNTS = ("separating", "bonded")


@dataclass(frozen=True)
class BarRig:
    """The whole rig: bar, spacer, raster base with the sensor, projectiles, launcher, and how the
    object is mounted on the bar's end (MOUNTS)."""

    bar: Segment = field(default_factory=lambda: Segment("Ti-6Al-4V", 1.6, 0.016))
    spacer: Segment | None = field(default_factory=lambda: Segment("Al-7075", 0.003, 0.016))
    base: Segment = field(default_factory=lambda: Segment("Ti-6Al-4V", 0.010, 0.016))  # the raster base
    sensor_mass_kg: float = 0.005  # the accelerometer on the base's far face
    projectiles: tuple[Projectile, ...] = field(default_factory=_paper_projectiles)
    launcher: Launcher = field(default_factory=Launcher)
    mount: str = "separating"

    def __post_init__(self) -> None:
        if self.mount not in MOUNTS:
            raise ValueError(f"the mount must be one of {', '.join(MOUNTS)}, got {self.mount!r}")
        if self.sensor_mass_kg < 0:
            raise ValueError(f"the sensor's mass must not be negative, got {self.sensor_mass_kg}")
        if not self.projectiles:
            raise ValueError("a rig needs at least one projectile")

    def projectile(self, number: int) -> Projectile:
        for p in self.projectiles:
            if p.number == number:
                return p
        raise ValueError(f"the rig has no projectile No. {number} (it has "
                         f"{', '.join(str(p.number) for p in self.projectiles)})")

    @property
    def object_mass_kg(self) -> float:
        """The calibrated object: the raster base and the accelerometer."""
        return self.base.mass_kg + self.sensor_mass_kg


PAPER_RIG = BarRig()

"""One-dimensional elastic waves in piecewise-uniform rods, exactly, on a travel-time lattice.

Each rod segment is cut into cells that a wave crosses in one time step Δt (cell length
c₀·Δt: shorter cells in slower materials). A cell carries a right-going and a left-going
force wave (compression positive; particle velocity v = (f − g)/Z with Z = ρc₀A). At every
boundary between cells the waves scatter as force and velocity continuity demand:

    v_J = 2(f_i − g_{i+1})/(Z_i + Z_{i+1}),  F_J = 2f_i − Z_i·v_J,
    g_i' = F_J − f_i (reflected),  f_{i+1}' = F_J − g_{i+1} (transmitted),

so an impedance step reflects (Z₂ − Z₁)/(Z₁ + Z₂) and transmits 2Z₂/(Z₁ + Z₂) of a force wave.
This is the method of characteristics of the 1-D wave equation and has no numerical
dispersion (a finite-difference scheme smears a step over many cells); the only
approximation is rounding each segment to a whole number of cells (`cells_of`).

Contacts (projectile–spacer, bar–raster base) carry compression only: where the bonded
junction would go into tension both faces become free, and they touch again only when the gap
their velocities open has closed. A free end reflects −f; a lumped mass m on an end obeys
m·dv/dt = F (implicit Euler per step); a semi-infinite rod absorbs what reaches it.

Plain Python over the time steps with NumPy over the cells: the rods here have tens to a few
hundred cells and a shot needs a few thousand steps; no library offers this scattering lattice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hopkinson.analysis.bar.geometry import CONTACT_REFERENCE_M, Segment

MIN_CELLS = 8  # the shortest segment is cut into at least this many cells
STEP_SPEED_M_S = 250.0  # a stiffening contact's step is set for impacts up to this speed (a gas gun's reach)


def step_for(segments: list[Segment], sample_interval_s: float) -> tuple[float, int]:
    """The lattice's time step: `sample_interval_s`/m for the smallest whole m that gives the
    shortest segment at least MIN_CELLS cells; and m."""
    shortest = min(s.length_m / s.props.bar_speed_m_s for s in segments)
    m = max(1, math.ceil(sample_interval_s * MIN_CELLS / shortest))
    return sample_interval_s / m, m


def cells_of(segments: list[Segment], dt: float) -> np.ndarray:
    """Each cell's impedance Z = ρc₀A, segment by segment (each rounded to whole cells, ≥ 1)."""
    z = [np.full(max(1, round(s.length_m / (s.props.bar_speed_m_s * dt))), s.impedance_kg_s) for s in segments]
    return np.concatenate(z)


def _one_cell(rod: Segment, dt: float) -> Segment:
    """One lattice cell of `rod` (a wave crosses it in dt): what stands for a semi-infinite rod,
    whose far end the waves never reach within the time followed."""
    return Segment(rod.material, rod.props.bar_speed_m_s * dt, rod.diameter_m)


@dataclass
class Contact:
    """A compression-only junction (between cell `index` and `index + 1`): rigid (its gap, m, while
    open), or through a contact spring of secant stiffness `stiffness_n_m` at 1 mm and `exponent`
    p (F = k·δ₁·(δ/δ₁)^p; its compression δ, m: the faces touch while it is positive)."""

    index: int
    open: bool = False
    gap_m: float = 0.0
    stiffness_n_m: float | None = None
    compression_m: float = 0.0
    exponent: float = 1.0


class Lattice:
    """The waves of a chain of cells; `step` advances them by one Δt."""

    def __init__(self, impedance: np.ndarray, dt: float, contact: int | None = None,
                 contact_stiffness_n_m: float | None = None, contact_exponent: float = 1.0) -> None:
        self.z = np.asarray(impedance, dtype=float)
        self.dt = dt
        self.f = np.zeros(self.z.size)  # right-going force waves, at each cell's right end
        self.g = np.zeros(self.z.size)  # left-going, at each cell's left end
        self._zl, self._zr = self.z[:-1], self.z[1:]
        self._sum = self._zl + self._zr
        self.contact = (Contact(contact, stiffness_n_m=contact_stiffness_n_m, exponent=contact_exponent)
                        if contact is not None else None)
        self.contact_force = 0.0
        self.end_velocity = 0.0  # the right end's velocity (with a lumped mass on it)

    def set_moving(self, cells: slice, speed_m_s: float) -> None:
        """Cells moving rigidly at `speed_m_s` without stress (a flying projectile)."""
        self.f[cells] = 0.5 * self.z[cells] * speed_m_s
        self.g[cells] = -0.5 * self.z[cells] * speed_m_s

    def momentum(self, cells: slice) -> float:
        """Σ m·v over the cells (each cell's mass is Z·Δt)."""
        return float(np.sum(self.f[cells] - self.g[cells]) * self.dt)

    def step(self, left_in: float | None = None, right_mass_kg: float | None = None) -> float:
        """One Δt. left_in: the force wave entering the first cell from a semi-infinite rod on
        the left (None: a free left end). right_mass_kg: a lumped mass on the right end (0: a
        free end; None: a semi-infinite rod absorbs). Returns the force wave leaving on the
        right (0 unless absorbed)."""
        f, g = self.f, self.g
        fi, gi1 = f[:-1], g[1:]
        v_j = 2.0 * (fi - gi1) / self._sum
        force = 2.0 * fi - self._zl * v_j
        g_new = np.empty_like(g)
        f_new = np.empty_like(f)
        g_new[:-1] = force - fi
        f_new[1:] = force - gi1
        c = self.contact
        if c is not None and c.stiffness_n_m is not None:
            # a contact spring (the faces' asperities, a shaped tip): F = k·δ₁·(δ/δ₁)^p, never pulling;
            # each face reflects its wave about F, and the compression grows with their closing speed
            j = c.index
            spring = c.stiffness_n_m * CONTACT_REFERENCE_M * (max(c.compression_m, 0.0) / CONTACT_REFERENCE_M) ** c.exponent
            g_new[j] = spring - fi[j]
            f_new[j + 1] = spring - gi1[j]
            closing = (2.0 * fi[j] - spring) / self._zl[j] - (spring - 2.0 * gi1[j]) / self._zr[j]
            c.compression_m += closing * self.dt
            c.open = c.compression_m <= 0.0
            self.contact_force = spring
        elif c is not None:
            j = c.index
            bonded = force[j]
            if c.open and c.gap_m <= 0.0 and bonded >= 0.0:
                c.open = False
            elif not c.open and bonded < 0.0:
                c.open, c.gap_m = True, 0.0
            if c.open:  # two free faces: each reflects its wave, the gap opens at their speeds
                g_new[j] = -fi[j]
                f_new[j + 1] = -gi1[j]
                c.gap_m += (-2.0 * gi1[j] / self._zr[j] - 2.0 * fi[j] / self._zl[j]) * self.dt
                self.contact_force = 0.0
            else:
                self.contact_force = float(bonded)
        f_new[0] = -g[0] if left_in is None else left_in
        leaving = 0.0
        if right_mass_kg is None:
            leaving = float(f[-1])
            g_new[-1] = 0.0
        else:
            z_end, m = self.z[-1], right_mass_kg
            self.end_velocity = (m * self.end_velocity / self.dt + 2.0 * f[-1]) / (m / self.dt + z_end)
            g_new[-1] = f[-1] - z_end * self.end_velocity
        self.f, self.g = f_new, g_new
        return leaving


@dataclass(frozen=True)
class Impact:
    """The force wave the impact sends into the bar, sampled every `sample_interval_s`."""

    force_n: np.ndarray
    sample_interval_s: float
    contact_s: float  # how long the projectile pushed (until it left for good, or the end)
    projectile_momentum_lost: float  # m·(v₀ − v_end), kg·m/s
    projectile_speed_after_m_s: float


def impact_force(projectile: list[Segment], spacer: Segment | None, bar: Segment, speed_m_s: float,
                 sample_interval_s: float, max_duration_s: float = 1e-3,
                 contact_stiffness_n_m: float | None = None, contact_exponent: float = 1.0) -> Impact:
    """The force wave entering the bar when `projectile` (segments from its impact face
    backwards) strikes the spacer (or the bar) at `speed_m_s`; the bar is semi-infinite here
    (its far end is reached after the impact is over). Sampled every `sample_interval_s`
    (block means of the lattice's finer steps)."""
    rear_first = list(reversed(projectile))
    front = [spacer] if spacer is not None else []

    def chain(dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(projectile's cells, spacer's cells, all cells with one cell of the bar) at step dt."""
        z_proj = cells_of(rear_first, dt)
        z_front = cells_of(front, dt) if front else np.zeros(0)
        return z_proj, z_front, np.concatenate([z_proj, z_front, cells_of([_one_cell(bar, dt)], dt)])

    dt, m = step_for([*rear_first, *front], sample_interval_s)
    z_proj, z_front, z = chain(dt)
    if contact_stiffness_n_m is not None:  # an explicit spring: Δt·k·(1/Z₁ + 1/Z₂) < 2 keeps it stable
        # the step for the fastest likely impact, not this one's: a step that changed with the speed
        # would make the pulse jump where it halves, and a plan's search for a speed could not settle
        stiffest = _stiffest_n_m(contact_stiffness_n_m, contact_exponent, projectile,
                                 max(abs(speed_m_s), STEP_SPEED_M_S))
        limit = 1.0 / (stiffest * (1.0 / z_proj[-1] + 1.0 / z[z_proj.size]))
        while dt > limit:
            dt, m = dt / 2.0, m * 2
        z_proj, z_front, z = chain(dt)
    lattice = Lattice(z, dt, contact=z_proj.size - 1, contact_stiffness_n_m=contact_stiffness_n_m,
                      contact_exponent=contact_exponent)
    projectile_cells = slice(0, z_proj.size)
    lattice.set_moving(projectile_cells, speed_m_s)
    p0 = lattice.momentum(projectile_cells)
    # after the projectile leaves, the spacer rings out into the bar: follow it for a while
    settle = max(20 * (z_front.size + 1), 4 * m)
    steps = int(max_duration_s / dt)
    out = np.zeros(steps)
    left_at = None
    for n in range(steps):
        out[n] = lattice.step()
        c = lattice.contact
        assert c is not None
        if c.open and left_at is None:
            left_at = n
        elif not c.open:
            left_at = None
        if left_at is not None and n - left_at > settle and (c.gap_m > 0 or c.stiffness_n_m is not None):
            out = out[: n + 1]
            break
    p_end = lattice.momentum(projectile_cells)
    mass = sum(s.mass_kg for s in projectile)
    usable = out.size // m * m
    blocks = out[:usable].reshape(-1, m).mean(axis=1)
    return Impact(blocks, sample_interval_s, (left_at if left_at is not None else out.size) * dt, p0 - p_end,
                  p_end / mass)


def _stiffest_n_m(stiffness_n_m: float, exponent: float, projectile: list[Segment], speed_m_s: float) -> float:
    """The contact's largest tangent stiffness p·k·(δ/δ₁)^(p−1) in this impact: at most at the
    compression that would hold the projectile's whole kinetic energy (k·δ₁·δ^(p+1)/((p+1)·δ₁^p)
    = ½mv²; the bar takes part of it, so the real compression is smaller)."""
    if exponent == 1.0:
        return stiffness_n_m
    energy = 0.5 * sum(s.mass_kg for s in projectile) * speed_m_s**2
    delta = ((exponent + 1.0) * energy * CONTACT_REFERENCE_M ** (exponent - 1.0) / stiffness_n_m) ** (1.0 / (exponent + 1.0))
    return exponent * stiffness_n_m * (delta / CONTACT_REFERENCE_M) ** (exponent - 1.0)


@dataclass(frozen=True)
class ObjectMotion:
    """The calibrated object's motion: its acceleration and velocity, and the force that moves it
    (separating: the contact's, over the object's whole mass; bonded: the base face's on the
    sensor)."""

    acceleration_m_s2: np.ndarray
    velocity_m_s: np.ndarray
    contact_force_n: np.ndarray
    sample_interval_s: float
    separation_s: float | None  # when it left the bar for good (None: still touching at the end)


def object_motion(incident_force_n: np.ndarray, bar: Segment, base: Segment, sensor_mass_kg: float,
                  sample_interval_s: float, bonded: bool = False) -> ObjectMotion:
    """The raster base (with the sensor's mass on its far face) on the bar's end, struck by the
    incident force wave. Separating (`bonded` False, the paper's rig): the contact carries
    compression only, so the object flies off once the reflected wave would pull on it (the
    paper's Eqs. 27–30); its acceleration is the contact force over its whole mass (the base's
    own ringing is not in it). Bonded (`bonded_motion`): the base is screwed or glued to the
    end face and follows the bar through the whole wave."""
    if bonded:
        return bonded_motion(incident_force_n, bar, base, sensor_mass_kg, sample_interval_s)
    dt, m, z = _end_cells(bar, base, sample_interval_s)
    lattice = Lattice(z, dt, contact=0)
    mass = base.mass_kg + sensor_mass_kg
    incoming = np.repeat(np.asarray(incident_force_n, dtype=float), m)
    # the fastest the bar's free end can still move: twice the particle velocity of the largest
    # compression yet to arrive
    reachable_m_s = 2.0 * np.maximum(np.maximum.accumulate(incoming[::-1])[::-1], 0.0) / z[0]
    force = np.zeros(incoming.size)
    momentum = 0.0
    separated_at = None
    for n in range(incoming.size):
        lattice.step(left_in=float(incoming[n]), right_mass_kg=sensor_mass_kg)
        force[n] = lattice.contact_force
        momentum += force[n] * dt
        c = lattice.contact
        assert c is not None
        if c.open and separated_at is None and n > 0 and np.any(force[:n] > 0):
            separated_at = n
        elif not c.open:
            separated_at = None
        if separated_at is not None and c.gap_m > 0.0 and momentum / mass > reachable_m_s[n]:
            break  # flying off: the bar's end can no longer catch it up
    usable = force.size // m * m
    force_out = force[:usable].reshape(-1, m).mean(axis=1)
    accel = force_out / mass
    velocity = np.cumsum(accel) * sample_interval_s
    return ObjectMotion(accel, velocity, force_out, sample_interval_s,
                        separated_at * dt if separated_at is not None else None)


def _end_cells(bar: Segment, base: Segment, sample_interval_s: float) -> tuple[float, int, np.ndarray]:
    """The bar's end and the base as lattice cells: (step, steps per sample, impedances), the bar
    one cell standing for a semi-infinite rod."""
    dt, m = step_for([base], sample_interval_s)
    return dt, m, np.concatenate([cells_of([_one_cell(bar, dt)], dt), cells_of([base], dt)])


# The bonded end's impulse response is followed until it has fallen below this fraction of its
# largest value (the sensor's mass on the base rings out into the bar within microseconds).
IMPULSE_TAIL = 1e-12


def bonded_motion(incident_force_n: np.ndarray, bar: Segment, base: Segment, sensor_mass_kg: float,
                  sample_interval_s: float) -> ObjectMotion:
    """The sensor's mounting face (the base's far face, the sensor's mass on it) when the base is
    bonded to the bar's end: the joint carries tension too, nothing separates, and the face
    moves with the bar through the whole wave: forward while the compression arrives, back to
    rest as the wave reflects (a light end doubles the particle velocity, v ≈ 2F/Z), so its
    acceleration is bipolar with no net velocity change, the shape of PTB's record (its sensor
    stays on the bar). The acceleration is the face's (what a sensor mounted there and an
    interferometer spot beside it see), not the base's mean.

    With no contact to open the lattice is linear and time-invariant, so the face's velocity is
    the incident wave convolved with the lattice's own impulse response (followed until it has
    rung out, IMPULSE_TAIL): the same numbers as stepping the whole record, in a fraction of
    the time."""
    dt, m, z = _end_cells(bar, base, sample_interval_s)
    lattice = Lattice(z, dt)
    incoming = np.repeat(np.asarray(incident_force_n, dtype=float), m)
    response: list[float] = []
    largest = 0.0
    for n in range(incoming.size):
        lattice.step(left_in=1.0 if n == 0 else 0.0, right_mass_kg=sensor_mass_kg)
        v = lattice.end_velocity
        response.append(v)
        largest = max(largest, abs(v))
        if n > 2 * z.size and largest > 0 and np.all(np.abs(lattice.f) + np.abs(lattice.g) <= IMPULSE_TAIL * largest
                                                     * z.max()) and abs(v) <= IMPULSE_TAIL * largest:
            break
    h = np.asarray(response)
    size = int(2 ** math.ceil(math.log2(incoming.size + h.size)))
    fine_v = np.fft.irfft(np.fft.rfft(incoming, size) * np.fft.rfft(h, size), size)[: incoming.size]
    usable = fine_v.size // m * m
    velocity = np.concatenate(([0.0], fine_v[m - 1: usable: m]))  # at the end of each sample's steps
    accel = np.diff(velocity) / sample_interval_s
    face_force = accel * sensor_mass_kg
    return ObjectMotion(accel, velocity[1:], face_force, sample_interval_s, None)

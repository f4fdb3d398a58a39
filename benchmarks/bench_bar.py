"""Bar model speed: one shot predicted (projectile No. 3 of the paper's rig, 2 ms at 10 MS/s:
impact, dispersion, separation) against a direct explicit finite-difference solution of the
same rods in the same run.

The finite-difference baseline is the textbook staggered velocity–stress scheme of the 1-D wave
equation ρA·∂v/∂t = ∂(Aσ)/∂x, ∂σ/∂t = E·∂v/∂x over projectile, bar and raster base on a uniform
grid (Δx = 0.25 mm, Courant number 0.9 in the fastest material), with the same contacts
(compression only) and the same sensor mass on the base's far face and the same 2 ms; it has no geometric dispersion (the bar model adds it in
the frequency domain at no extra cost), so it does less physics than the model it is timed against.
Its pulse is printed beside the model's as a check that both solve the same problem.

The last line is one JSON object.
"""

from __future__ import annotations

import dataclasses
import json
import time

import numpy as np

from hopkinson.analysis.bar import PAPER_RIG, predict_shot
from hopkinson.analysis.bar import predict as predict_module
from hopkinson.analysis.bar.dispersion import _table

DT = 1e-7
DURATION_S = 2e-3


def finite_difference(speed_m_s: float, dx: float = 0.25e-3) -> tuple[float, float, float]:
    """(peak acceleration of the object, its Δv, seconds) by explicit FD, rigid contacts."""
    rig = PAPER_RIG
    proj = rig.projectile(3)
    pieces = [*reversed(proj.segments), rig.bar, rig.base]
    rho = np.concatenate([np.full(max(1, round(s.length_m / dx)), s.props.density_kg_m3) for s in pieces])
    young = np.concatenate([np.full(max(1, round(s.length_m / dx)), s.props.youngs_modulus_pa) for s in pieces])
    area = np.concatenate([np.full(max(1, round(s.length_m / dx)), s.area_m2) for s in pieces])
    n_proj = sum(max(1, round(s.length_m / dx)) for s in reversed(proj.segments))
    n_base = max(1, round(rig.base.length_m / dx))
    n = rho.size
    c_max = float(np.max(np.sqrt(young / rho)))
    dt = 0.9 * dx / c_max
    steps = int(DURATION_S / dt)
    v = np.zeros(n)  # velocity at cell centres
    v[:n_proj] = speed_m_s
    force = np.zeros(n + 1)  # A·σ at the cell faces (compression positive), free ends
    mass = rho * area * dx
    mass[-1] += rig.sensor_mass_kg  # the accelerometer on the base's far face
    stiffness = 2.0 / (dx / (young[:-1] * area[:-1]) + dx / (young[1:] * area[1:]))  # series EA/dx
    contacts = [n_proj, n - n_base]  # the faces between projectile|bar and bar|base
    base_v = []
    pushed, separated_at = False, None
    started = time.perf_counter()
    for step in range(steps):
        force[1:-1] += dt * stiffness * (v[:-1] - v[1:])
        for j in contacts:  # compression only
            if force[j] < 0:
                force[j] = 0.0
        v += dt * (force[:-1] - force[1:]) / mass
        base_v.append(float(np.sum(mass[-n_base:] * v[-n_base:]) / np.sum(mass[-n_base:])))
        pushed = pushed or force[contacts[1]] > 0
        if pushed and separated_at is None and force[contacts[1]] == 0:
            separated_at = step  # the object leaves the bar (a later re-contact is not the pulse)
    seconds = time.perf_counter() - started
    velocity = np.asarray(base_v)
    accel = np.diff(velocity) / dt
    delta_v = float(velocity[separated_at if separated_at is not None else -1])
    return float(np.max(np.convolve(accel, np.ones(25) / 25, mode="same"))), delta_v, seconds


def main() -> None:
    speed = 10.0
    started = time.perf_counter()
    _table(round(PAPER_RIG.bar.props.poisson_ratio, 6))  # the Pochhammer–Chree table, once per material
    table_s = time.perf_counter() - started
    timings = []
    for _ in range(5):
        predict_module._shot.cache_clear()
        started = time.perf_counter()
        shot = predict_shot(PAPER_RIG, 3, speed_m_s=speed, sample_interval_s=DT, duration_s=DURATION_S)
        timings.append(time.perf_counter() - started)
    model_s = float(np.median(timings))
    started = time.perf_counter()
    predict_shot(PAPER_RIG, 3, speed_m_s=speed)  # the same shot again: cached
    cached_s = time.perf_counter() - started
    rigid = dataclasses.replace(PAPER_RIG.projectile(3), contact_stiffness_n_m=None)
    flat_rig = dataclasses.replace(PAPER_RIG, projectiles=(rigid,))
    flat = predict_shot(flat_rig, 3, speed_m_s=speed, dispersion=False)
    fd_peak, fd_dv, fd_s = finite_difference(speed)
    print(f"bar model, projectile No. 3, 2 ms at 10 MS/s: {model_s * 1e3:.1f} ms per shot (median of 5, "
          f"Pochhammer–Chree table {table_s * 1e3:.0f} ms once per material; the same shot again {cached_s * 1e3:.2f} ms)")
    print(f"  peak {shot.peak_m_s2 / 9.80665:,.0f} g at {speed:g} m/s, δ = {shot.equivalent_width_s * 1e6:.1f} µs")
    print(f"finite differences, same rods (rigid flat contacts, no dispersion), Δx = 0.25 mm: {fd_s:.2f} s")
    print(f"  its object Δv {fd_dv:.3f} m/s against the lattice's {flat.delta_v_m_s:.3f} m/s (same physics)")
    print(f"ratio: the bar model takes {model_s / fd_s:.4f}× the finite-difference time ({fd_s / model_s:.0f}× faster)")
    print(json.dumps({"model_s": model_s, "table_s": table_s, "cached_s": cached_s, "finite_difference_s": fd_s,
                      "ratio_model_vs_fd": model_s / fd_s, "under_50_ms": model_s < 0.05,
                      "fd_delta_v_m_s": fd_dv, "lattice_delta_v_m_s": flat.delta_v_m_s, "fd_peak_m_s2": fd_peak,
                      "lattice_peak_m_s2": flat.peak_m_s2}))


if __name__ == "__main__":
    main()

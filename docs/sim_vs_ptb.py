"""A simulated shock record beside PTB's real one (docs/bar-physics.md, "Realistic simulated records").

    .venv/bin/python -m pip install PyDynamic      # only for this figure: PTB's record ships in it
    .venv/bin/python docs/sim_vs_ptb.py [--out docs/sim-vs-ptb.png] [--projectile 1] [--pressure-bar 4]

PTB's record (PyDynamic, examples/Shock calibration): the reference acceleration (laser
interferometer, 10 MS/s) and the sensor's charge output. The simulated one is one shot of the
simulated world of config/sim.toml (its [world.realism] effects on), captured at 100 MS/s and
reduced to 10 MS/s by the analysis chain exactly as a rig's shot is. Both are normalised to their peaks;
the spectra are in dB of each signal's own largest spectral value.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FS_HZ = 10e6


@dataclass
class _Settings:
    sample_rate_hz: float
    record_length: int
    pre_trigger_samples: int


def ptb_record() -> tuple[np.ndarray, np.ndarray]:
    """PTB's reference acceleration and sensor output from the installed PyDynamic."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import PyDynamic
    folder = Path(PyDynamic.__file__).parent / "examples" / "Shock calibration"
    return np.loadtxt(folder / "measured_input_accel.txt"), np.loadtxt(folder / "measured_output_accel.txt")


def simulated_record(projectile: int, pressure_bar: float, n: int, pre: int, seed: int = 1
                     ) -> tuple[np.ndarray, np.ndarray, dict]:
    """One realistic simulated shot, reduced: the reference acceleration and the response (m/s²)."""
    import dataclasses

    from hopkinson.analysis.reduce import SensorChannel, reduce_sensors
    from hopkinson.drivers.sim.world import World
    from hopkinson.rig.config import load_sim_config

    params = dataclasses.replace(load_sim_config(REPO / "config" / "sim.toml").world, seed=seed)
    t = [0.0]
    world = World(params, clock=lambda: t[0])
    world.load_projectile(projectile)
    world.set_pressure_setpoint_bar(pressure_bar)
    world.set_fill_valve(True)
    t[0] += 100.0
    world.set_fill_valve(False)
    world.amp_auto_zero()
    world.set_fire_valve(True)
    raw_hz = 10 * FS_HZ  # the rig's digitizer: the beat needs 100 MS/s; reduced to 10 MS/s below
    channels = world.capture(_Settings(raw_hz, 10 * n, 10 * pre))
    truth = world.last_shot_truth
    sensitivity = truth["sensitivity_v_per_m_s2"]
    reduced = reduce_sensors(channels[1], {"response": SensorChannel(channels[2], truth["amplifier_gain"], sensitivity)},
                             1.0 / raw_hz, quadrature_v=channels.get(3), grating_pitch_m=truth["grating_pitch_m"],
                             orders=tuple(truth["orders"]),
                             sample_rate_hz=FS_HZ)["response"]
    return np.asarray(reduced.record.reference), np.asarray(reduced.record.response), truth


def spectrum_db(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    spec = np.abs(np.fft.rfft(x))
    f = np.fft.rfftfreq(x.size, 1.0 / FS_HZ)
    return f, 20 * np.log10(np.maximum(spec / spec.max(), 1e-12))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=REPO / "docs" / "sim-vs-ptb.png")
    p.add_argument("--projectile", type=int, default=1)
    p.add_argument("--pressure-bar", type=float, default=4.0)
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref_ptb, out_ptb = ptb_record()
    n = ref_ptb.size
    onset = int(np.flatnonzero(np.abs(ref_ptb) > 0.05 * np.max(np.abs(ref_ptb)))[0])
    ref_sim, out_sim, truth = simulated_record(args.projectile, args.pressure_bar, n, onset)
    t_ms = np.arange(n) / FS_HZ * 1e3
    fig, axes = plt.subplots(3, 2, figsize=(11, 9.5), sharex="row")
    for col, (name, ref, out) in enumerate((("PTB (PyDynamic example, real)", ref_ptb, out_ptb),
                                            ("simulated (config/sim.toml, realism on)", ref_sim, out_sim))):
        peak_i = int(np.argmax(np.abs(ref)))
        r, y = ref / ref[peak_i], out / out[int(np.argmax(np.abs(out)))]
        ax = axes[0, col]
        ax.plot(t_ms, r, lw=0.8, label="reference (interferometer)")
        ax.plot(t_ms, y, lw=0.8, alpha=0.8, label="sensor output")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("time (ms)")
        ax.set_ylabel("÷ peak")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        ax = axes[1, col]
        ax.plot(t_ms, 100 * r, lw=0.6, label="reference")
        ax.plot(t_ms, 100 * y, lw=0.6, alpha=0.7, label="sensor output")
        ax.set_ylim(-6, 6)
        ax.set_xlabel("time (ms)")
        ax.set_ylabel("% of peak (zoomed: after the pulse)")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        ax = axes[2, col]
        for x, label in ((r, "reference"), (y, "sensor output")):
            f, db = spectrum_db(x)
            ax.plot(f / 1e3, db, lw=0.8, label=label)
        for f_null in (28, 42, 50):
            ax.axvline(f_null, color="0.6", lw=0.6, ls=":")
        ax.set_xlim(0, 120)
        ax.set_ylim(-80, 3)
        ax.set_xlabel("frequency (kHz)  (dotted: PTB's nulls at 28, 42, 50 kHz)")
        ax.set_ylabel("dB of the largest value")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle(f"PTB's real shock record against a simulated one (projectile No. {truth['projectile']}, "
                 f"{truth['pressure_bar']:.2g} bar, pulse source '{truth['pulse_source']}')", fontsize=11)
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

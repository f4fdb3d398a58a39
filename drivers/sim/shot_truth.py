"""A fired shot of the simulated world and its truth (`World.last_shot_truth`, JSON-ready)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.real_records import PulseShape
from hopkinson.drivers.sim.sensor_truth import sensor_truth
from hopkinson.drivers.sim.shock import G_M_S2
from hopkinson.drivers.sim.world_params import SignalParams, WorldParams


@dataclass(frozen=True)
class FiredShot:
    """One launched shot: what was fired, the sensor model and the amplifier at that moment."""

    number: int
    fired_at_s: float
    pressure_bar: float
    projectile: int
    speed_m_s: float
    delta_v_m_s: float
    width_s: float
    peak_m_s2: float
    truth: AccelerometerTruth
    gain: float
    excitation_v: float
    bridge_sensitivity_v_per_m_s2: float
    output_offset_v: float
    truth_2: AccelerometerTruth | None = None  # the second sensor's, when there is one
    pulse: PulseShape | None = None  # the object's acceleration (the pulse source's)
    speed_factor: float = 1.0  # the shot-to-shot scatter drawn for the projectile's speed
    sine_modes: tuple[Mode, ...] | None = None  # the sensor's modes before mounting (realism's mount)



def truth_dict(shot: FiredShot, params: WorldParams) -> dict[str, Any]:
    """The shot's truth, JSON-ready (`World.last_shot_truth`)."""
    signals = params.signals
    out = _shot_truth_dict(shot, signals)
    if signals.quadrature:  # the Heydemann parameters of the (doppler, doppler_quadrature) ellipse
        q = signals.quadrature_output()
        out["quadrature"] = {"offset_1_v": signals.pm_dc_offset_v, "offset_2_v": q.offset_v,
                             "amplitude_v": signals.pm_amplitude_v, "amplitude_ratio": 1.0 / q.gain_ratio,
                             "phase_error_rad": q.phase_error_rad}
    out["accelerometer"]["nonlinearity_per_m_s2"] = params.accelerometer.nonlinearity_per_m_s2
    realism = params.realism
    out["sensor"] = sensor_truth(  # the figures as the analysis reports them (drivers/sim/sensor_truth.py)
        shot.truth, realism.mount.asymmetry_rel if realism.enabled and realism.mount.enabled else 0.0,
        realism.transverse.sensitivity_rel if realism.enabled and realism.transverse.enabled else 0.0,
        params.accelerometer.nonlinearity_per_m_s2)
    assert shot.pulse is not None
    out["pulse_source"] = "ideal" if not params.realism.enabled else params.realism.pulse_source
    out["pulse"]["shape"] = shot.pulse.shape
    if params.realism.enabled:  # every effect's switch and size, and (at capture) what was drawn
        out["realism"] = {**params.realism.to_dict(), "speed_factor": shot.speed_factor}
        if shot.sine_modes is not None:
            out["accelerometer_sine_calibrated"] = {
                "modes": [{"natural_frequency_hz": m.natural_frequency_hz, "damping_ratio": m.damping_ratio}
                          for m in shot.sine_modes]}
    if shot.truth_2 is not None:
        s2 = params.accelerometer_2
        out["accelerometer_2"] = {**_model_dict(shot.truth_2), "sensitivity_v_per_m_s2": s2.sensitivity_v_per_m_s2,
                                  "conditioner_gain": s2.conditioner_gain}
    return out


def _model_dict(truth: AccelerometerTruth) -> dict[str, Any]:
    return {
        "modes": [{"natural_frequency_hz": m.natural_frequency_hz, "damping_ratio": m.damping_ratio}
                  for m in truth.modes],
        "lowpass_hz": truth.lowpass_hz,
        "lowpass_order": truth.lowpass_order,
        "sensitivity": truth.sensitivity,
        "zero_shift": truth.zero_shift,
    }


def _shot_truth_dict(shot: FiredShot, signals: SignalParams) -> dict[str, Any]:
    return {
        "shot_number": shot.number,
        "fired_at_sim_s": shot.fired_at_s,
        "pressure_bar": shot.pressure_bar,
        "projectile": shot.projectile,
        "projectile_speed_m_s": shot.speed_m_s,
        "pulse": {"shape": "bipolar" if signals.pulse_bipolar_ratio else "half_sine", "peak_m_s2": shot.peak_m_s2,
                  "width_s": shot.width_s, "start_s": 0.0, "bipolar_ratio": signals.pulse_bipolar_ratio},
        "channel_skew_s": signals.channel_skew_s,
        "response_drift_v_per_s": signals.response_drift_v_per_s,
        "peak_acceleration_m_s2": shot.peak_m_s2,
        "peak_g": shot.peak_m_s2 / G_M_S2,
        "pulse_width_s": shot.width_s,
        "delta_velocity_m_s": shot.delta_v_m_s,
        "accelerometer": _model_dict(shot.truth),
        "amplifier_gain": shot.gain,
        "excitation_v": shot.excitation_v,
        "sensitivity_v_per_m_s2": shot.bridge_sensitivity_v_per_m_s2,
        "output_offset_v": shot.output_offset_v,
        "grating_pitch_m": signals.grating_pitch_m,
        "orders": list(signals.orders),
    }


def reference_dict(time_s: np.ndarray, velocity: np.ndarray, acceleration: Callable[[np.ndarray], np.ndarray]
                    ) -> dict[str, list[float]]:
    """The true reference decimated to at most ~1 MS/s (JSON-sized)."""
    fs = 1.0 / (time_s[1] - time_s[0]) if time_s.size > 1 else 1.0
    step = max(1, int(round(fs / 1e6)))
    t = time_s[::step]
    return {
        "time_s": t.tolist(),
        "velocity_m_s": velocity[::step].tolist(),
        "acceleration_m_s2": acceleration(t).tolist(),
    }


def accelerometer_truth(truth: dict[str, Any], key: str = "accelerometer") -> AccelerometerTruth:
    """The AccelerometerTruth of a shot from its `last_shot_truth` dict (round trip); key
    "accelerometer_2" for the second sensor."""
    acc = truth[key]
    return AccelerometerTruth(
        modes=tuple(Mode(m["natural_frequency_hz"], m["damping_ratio"]) for m in acc["modes"]),
        lowpass_hz=acc["lowpass_hz"],
        lowpass_order=acc["lowpass_order"],
        sensitivity=acc["sensitivity"],
        zero_shift=acc["zero_shift"],
    )


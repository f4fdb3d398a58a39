"""What a fired shot of the simulated world puts on the digitizer's channels (V).

Channel 1: the PM beat (drivers/sim/doppler_beat.pm_beat); 2: the amplifier's output (the true
accelerometer model with the amplifier's gain, low-pass, offset and noise); 3: with [world.signals]
quadrature, the quadrature photodetector; 4: with [world.accelerometer_2], a second sensor's
conditioner output. With [world.realism] the records carry a real rig's effects (bar motion after
the pulse, the mount, a transverse drive, the interferometer chain; drivers/sim/real_records.py).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, coloured_noise, white_noise
from hopkinson.drivers.sim.doppler_beat import pm_beat
from hopkinson.drivers.sim.real_records import (
    MountParams,
    ShotMotion,
    mounted_input_m_s2,
    shot_motion,
)
from hopkinson.drivers.sim.shock import velocity_m_s
from hopkinson.drivers.sim.shot_truth import FiredShot
from hopkinson.drivers.sim.world_params import WorldParams

_NO_MOUNT = MountParams(enabled=False)  # the idealised world: the sensor as sine-calibrated


def shot_channels(params: WorldParams, shot: FiredShot, time_s: np.ndarray, fs: float
                  ) -> tuple[dict[int, np.ndarray], np.ndarray, ShotMotion | None]:
    """The channels (by number, V) a digitizer sampling at `fs` (Hz) sees at `time_s` (s from the
    pulse's start), the object's velocity there (m/s) and the realistic motions (None: idealised)."""
    rng = np.random.default_rng([params.seed, shot.number])
    sig = params.signals
    assert shot.pulse is not None
    motion = _motion(params, shot, time_s, fs)
    if motion is None:
        velocity = shot.pulse.velocity_m_s(time_s)
    else:  # what the interferometer reports, integrated from rest and brought to the digitizer's grid
        velocity = np.interp(time_s, motion.time_s, velocity_m_s(motion.measured_reference_m_s2,
                                                                  float(motion.time_s[1] - motion.time_s[0])))
    beat_options: dict[str, Any] = dict(amplitude_v=sig.pm_amplitude_v, dc_offset_v=sig.pm_dc_offset_v,
                                        fluctuation=sig.pm_fluctuation, snr_db=sig.pm_snr_db or None, rng=rng)
    channels: dict[int, np.ndarray] = {}
    if sig.quadrature:  # the extra channels draw from their own generators: channels 1, 2 stay as they were
        channels[1], channels[3] = pm_beat(
            velocity, 1.0 / fs, sig.grating_pitch_m, tuple(sig.orders), quadrature=sig.quadrature_output(),
            quadrature_rng=np.random.default_rng([params.seed, shot.number, 1]), **beat_options)
    else:
        channels[1] = pm_beat(velocity, 1.0 / fs, sig.grating_pitch_m, tuple(sig.orders), **beat_options)
    if motion is not None:  # the demodulator loses the beat's amplitude while the object jerks away
        gain = np.interp(time_s, motion.time_s, motion.beat_gain)
        channels[1] = sig.pm_dc_offset_v + (channels[1] - sig.pm_dc_offset_v) * gain
        if 3 in channels:
            channels[3] = sig.quadrature_offset_v + (channels[3] - sig.quadrature_offset_v) * gain
    channels[2] = _response_v(params, shot, time_s, fs, rng, motion)
    if shot.truth_2 is not None:
        channels[4] = _response_2_v(params, shot, time_s, fs, np.random.default_rng([params.seed, shot.number, 2]),
                                    motion)
    return channels, velocity, motion


def response_rate_hz(params: WorldParams, fs: float) -> float:
    """The internal rate of the response model and of the realistic motions."""
    return min(fs, params.signals.response_rate_hz)


def _internal_grid(params: WorldParams, time_s: np.ndarray, fs: float) -> np.ndarray:
    rate = response_rate_hz(params, fs)
    n_int = int(np.ceil((time_s[-1] - time_s[0]) * rate)) + 2
    return time_s[0] + np.arange(n_int) / rate


def _motion(params: WorldParams, shot: FiredShot, time_s: np.ndarray, fs: float) -> ShotMotion | None:
    """The shot's realistic motions on the internal grid (None in the idealised world)."""
    realism = params.realism
    if not realism.enabled:
        return None
    assert shot.pulse is not None
    sig = params.signals
    wavenumber = 2.0 * math.pi * (sig.orders[0] - sig.orders[1]) / sig.grating_pitch_m
    return shot_motion(_internal_grid(params, time_s, fs), shot.pulse, realism,
                       np.random.default_rng([params.seed, shot.number, 3]), abs(wavenumber))


def _response_v(params: WorldParams, shot: FiredShot, time_s: np.ndarray, fs: float, rng: np.random.Generator,
                motion: ShotMotion | None = None) -> np.ndarray:
    """Amplifier output (V) at the digitizer's times (`_sensor_output_v` of the first sensor)."""
    sig = params.signals
    return _sensor_output_v(params, shot, shot.truth, shot.gain * shot.bridge_sensitivity_v_per_m_s2, time_s, fs,
                            rng, offset_v=shot.output_offset_v, skew_s=sig.channel_skew_s,
                            drift_v_per_s=sig.response_drift_v_per_s, motion=motion,
                            nonlinearity_per_m_s2=params.accelerometer.nonlinearity_per_m_s2)


def _response_2_v(params: WorldParams, shot: FiredShot, time_s: np.ndarray, fs: float, rng: np.random.Generator,
                  motion: ShotMotion | None = None) -> np.ndarray:
    """The second sensor's conditioner output (V): its own model, gain and sensitivity."""
    s2 = params.accelerometer_2
    assert shot.truth_2 is not None
    return _sensor_output_v(params, shot, shot.truth_2, s2.conditioner_gain * s2.sensitivity_v_per_m_s2, time_s,
                            fs, rng, motion=motion)


def _sensor_output_v(params: WorldParams, shot: FiredShot, truth: AccelerometerTruth, scale_v_per_m_s2: float,
                     time_s: np.ndarray, fs: float, rng: np.random.Generator, *, offset_v: float = 0.0,
                     skew_s: float = 0.0, drift_v_per_s: float = 0.0, motion: ShotMotion | None = None,
                     nonlinearity_per_m_s2: float = 0.0) -> np.ndarray:
    """A sensor's conditioned output (V) at the digitizer's times: `truth` applied to the
    shot's acceleration, times `scale_v_per_m_s2`, with the noise of [world.signals].

    The accelerometer + low-pass model is run at `response_rate_hz` (≤ fs) and linearly
    interpolated to the digitizer's grid: its transfer-function form loses precision for
    6th-order models at 100 MS/s (poles within 1e-3 of z = 1), and the channel carries
    nothing above a few hundred kHz, so 10 MS/s with linear interpolation is exact to
    ~1e-4 of the signal.
    """
    sig = params.signals
    rate = response_rate_hz(params, fs)
    assert shot.pulse is not None
    if motion is None:
        t_int = _internal_grid(params, time_s, fs)
        accel = mounted_input_m_s2(shot.pulse.acceleration_m_s2(t_int), _NO_MOUNT, nonlinearity_per_m_s2)
        clean = truth.respond(accel, 1.0 / rate)
    else:  # the base's motion through the mount, and the transverse path into the same mode
        t_int = motion.time_s
        accel = mounted_input_m_s2(motion.base_m_s2, params.realism.mount, nonlinearity_per_m_s2)
        clean = truth.respond(accel, 1.0 / rate)
        transverse = params.realism.transverse
        if transverse.enabled and transverse.sensitivity_rel:
            clean = clean + transverse.sensitivity_rel * (truth.respond(motion.lateral_m_s2, 1.0 / rate)
                                                          - truth.zero_shift)
    clean = clean * scale_v_per_m_s2
    if sig.response_coloured_snr_db > 0:
        clean = clean + coloured_noise(clean, sig.response_coloured_snr_db, rng, sig.response_coloured_pole)
    # A skew shifts the response channel's sampling instants against the Doppler channel's.
    out = np.interp(time_s - skew_s, t_int, clean) + offset_v
    out = out + drift_v_per_s * (time_s - time_s[0])
    if sig.response_white_snr_db > 0:
        out = out + white_noise(out - offset_v, sig.response_white_snr_db, rng)
    limit = params.amplifier.output_limit_v
    return np.clip(out, -limit, limit)


"""The reduction with a quadrature interferometer (Heydemann-corrected arctangent) and with
several sensors on one reference, against simulated shots whose motion, ellipse and sensors
are known (drivers/sim): the quadrature path must give the reference as well as the PM-beat
path, and every sensor its own truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.reduce import SensorChannel, reduce_raw, reduce_sensors
from hopkinson.analysis.shot_analysis import ShotAnalysis, analyse_raw_shot
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.doppler_beat import QuadratureOutput, pm_beat
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2, velocity_m_s

DT = 1e-8  # 100 MS/s
START_S = 200e-6
WIDTH_S = 38.6e-6
FLAT = AccelerometerTruth(modes=(Mode(20.0e6, 0.7),))  # flat to far beyond the pulse
ELLIPSE = QuadratureOutput(offset_v=0.12, gain_ratio=0.85, phase_error_rad=math.radians(4.0))
# The reference against the closed-form truth over the pulse: RMS error and peak error, as a
# fraction of the peak. Both interferometer paths must meet it (the low-pass L of the
# differentiating filter accounts for ~0.25 % RMS at 100 000 g, the noise for more at 20 000 g).
RMS_TOL, PEAK_TOL = 6e-3, 3e-3


def motion(peak_g: float, n: int = 150_000):
    t = np.arange(n) * DT
    acc = half_sine_m_s2(t, WIDTH_S, peak_g * G_M_S2, START_S)
    return t, acc, velocity_m_s(acc, DT)


def photodetectors(velocity: np.ndarray, seed: int) -> np.ndarray:
    """(u1, u2): the PM beat and its quadrature partner (rows of one array)."""
    return pm_beat(velocity, DT, quadrature=ELLIPSE, rng=np.random.default_rng(seed),
                   quadrature_rng=np.random.default_rng(seed + 100), snr_db=30.0)


def reference_errors(reduction, t: np.ndarray, acc: np.ndarray, peak: float) -> tuple[float, float]:
    rec = reduction.record
    pulse = (rec.time_s > START_S - 20e-6) & (rec.time_s < START_S + WIDTH_S + 40e-6)
    rms = float(np.sqrt(np.mean((rec.reference - np.interp(rec.time_s, t, acc))[pulse] ** 2))) / peak
    return rms, abs(reduction.peak_acceleration_m_s2 / peak - 1.0)


@pytest.mark.parametrize(("peak_g", "seed"), [(100_000, 1), (20_000, 2)])
def test_quadrature_reference_is_as_good_as_the_pm_beat_against_the_truth(peak_g: float, seed: int) -> None:
    t, acc, vel = motion(peak_g)
    u1, u2 = photodetectors(vel, seed)
    response = FLAT.respond(acc, DT)
    pm = reduce_raw(u1, response, DT)
    quad = reduce_raw(u1, response, DT, quadrature_v=u2)
    peak = peak_g * G_M_S2
    for r in (pm, quad):
        rms, peak_error = reference_errors(r, t, acc, peak)
        assert rms < RMS_TOL and peak_error < PEAK_TOL, (r.reference.method, rms, peak_error)
        assert r.peak_velocity_m_s == pytest.approx(vel.max(), rel=1e-3)
        assert r.onset_time_s == pytest.approx(START_S, abs=3e-6)
    q = quad.quantities()
    assert (pm.quantities()["interferometer"], q["interferometer"]) == ("pm_beat", "quadrature")
    # The fitted ellipse is the simulated detectors' (Heydemann: G = r1/r2, α the quadrature error).
    e = q["quadrature"]
    assert e["offset_1_v"] == pytest.approx(0.15, abs=2e-3) and e["offset_2_v"] == pytest.approx(0.12, abs=2e-3)
    assert e["amplitude_ratio"] == pytest.approx(1 / 0.85, rel=5e-3)
    assert e["phase_error_deg"] == pytest.approx(4.0, abs=0.3)
    assert q["beat_peak_hz"] == pytest.approx(2 * vel.max() / 2e-6, rel=0.02)  # Δf = 2v/d at the peak


def test_reversed_wiring_gives_the_same_motion() -> None:
    """A negated second detector reverses the phase: the motion is still reported in its own
    direction, identical to the correctly wired pair's."""
    t, acc, vel = motion(50_000)
    u1, u2 = photodetectors(vel, 3)
    response = FLAT.respond(acc, DT)
    right = reduce_raw(u1, response, DT, quadrature_v=u2)
    reversed_ = reduce_raw(u1, response, DT, quadrature_v=2 * 0.12 - u2)
    assert (right.quantities()["quadrature"]["direction"], reversed_.quantities()["quadrature"]["direction"]) == (1, -1)
    np.testing.assert_allclose(reversed_.record.reference, right.record.reference,
                               atol=2e-3 * right.peak_acceleration_m_s2)


def test_bad_quadrature_channels_are_clear_errors() -> None:
    t, acc, vel = motion(50_000, n=60_000)
    u1, u2 = photodetectors(vel, 4)
    response = FLAT.respond(acc, DT)
    with pytest.raises(AnalysisError, match="doppler_quadrature channels differ in length"):
        reduce_raw(u1, response, DT, quadrature_v=u2[:-3])
    with pytest.raises(AnalysisError, match="quadrature interferometer: .*constant"):
        reduce_raw(u1, response, DT, quadrature_v=np.full(u1.size, 0.1))
    still = np.zeros_like(vel)
    s1, s2 = photodetectors(still, 5)
    with pytest.raises(AnalysisError, match="quadrature interferometer"):  # no fringes: no ellipse, no motion
        reduce_raw(s1, response, DT, quadrature_v=s2)
    with pytest.raises(AnalysisError, match="doppler_quadrature channel: clipped"):  # at the digitizer's full scale
        reduce_raw(u1, response, DT, quadrature_v=np.clip(u2, -0.2, 0.2), full_scale_v={"doppler_quadrature": (-0.2, 0.2)})
    _, fast_acc, fast = motion(200_000)  # fringes up to 48 MHz at 100 MS/s: 0.48 of a fringe per sample
    f1, f2 = photodetectors(fast, 6)
    with pytest.raises(AnalysisError, match="0.4. of a fringe per sample.*sample faster"):
        reduce_raw(f1, FLAT.respond(fast_acc, DT), DT, quadrature_v=f2)


def test_two_sensors_share_one_reference_and_keep_their_own_scaling() -> None:
    t, acc, vel = motion(60_000)
    u1, u2 = photodetectors(vel, 7)
    a = FLAT.respond(acc, DT) * 10.0 * 2e-7  # gain 10, 0.2 µV/(m/s²)
    b = FLAT.respond(acc, DT) * 20.0 * 1e-7 * 1.03  # its true sensitivity 3 % above nominal
    out = reduce_sensors(u1, {"response": SensorChannel(a, 10.0, 2e-7), "response_2": SensorChannel(b, 20.0, 1e-7)},
                         DT, quadrature_v=u2)
    first, second = out["response"], out["response_2"]
    assert first.record.reference is not second.record.reference
    np.testing.assert_array_equal(first.record.reference, second.record.reference)
    assert first.demodulation_bandwidth_hz == second.demodulation_bandwidth_hz
    assert first.shock_sensitivity == pytest.approx(1.0, rel=3e-3)
    assert second.shock_sensitivity == pytest.approx(1.03, rel=3e-3)


def test_a_failing_second_sensor_does_not_fail_the_first() -> None:
    """A second channel with a broken sample: the first sensor is analysed, the second's entry says why."""
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), lowpass_hz=200_000.0)
    t, acc, vel = motion(50_000, n=100_000)
    u1, u2 = photodetectors(vel, 8)
    rng = np.random.default_rng(9)
    first = truth.respond(acc, DT) * 10.0 * 2e-7
    first = first + rng.standard_normal(first.size) * 1e-5 * np.max(first)
    params = AnalysisOptions(amp_gain=10.0, sensitivity_v_per_m_s2=2e-7, uncertainty=False, max_order=6)
    broken = first.copy()
    broken[5000] = np.nan
    analysis = analyse_raw_shot(u1, first, DT, params, quadrature_v=u2, more_sensors={"response_2": (broken, params)})
    assert analysis.reduction["interferometer"] == "quadrature"
    assert not analysis.sensors and "response_2 channel has a NaN" in analysis.sensor_errors["response_2"]
    assert any("sensor response_2 not analysed" in w for w in analysis.warnings)
    data = analysis.to_dict()
    assert data["sensors"] == {"response_2": {"error": analysis.sensor_errors["response_2"]}}
    back = ShotAnalysis.from_dict(data)
    assert back.sensor_errors == analysis.sensor_errors and back.model.order == analysis.model.order

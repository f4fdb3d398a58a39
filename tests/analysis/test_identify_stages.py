"""Each stage of analysis.identify on its own (issue 17 item 6), against a truth the test builds:
a half-sine of known place and width driving a known continuous sensor (scipy.signal), white
noise of known level, a known drift, a known coherent motion, a known extra drive path."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from hopkinson.analysis.claims import claimed_modes, delay_findings
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.findings import FindingCode
from hopkinson.analysis.frequency_fit import OrderFit
from hopkinson.analysis.identify_stages import search_orders, weigh_model_error
from hopkinson.analysis.model import DiscreteModel, all_pole_numerator
from hopkinson.analysis.model_error import measure_model_error
from hopkinson.analysis.modes import has_doublet
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.order_search import (
    best_delay_branch,
    fit_orders,
    fit_structures,
    search_setup,
    settle_order,
)
from hopkinson.analysis.record_preparation import (
    Alignment,
    fitted_band,
    locate_pulse,
    measure_noise,
    prepare_record,
    realigned,
)
from hopkinson.analysis.records import Record
from hopkinson.analysis.structure import DelayMode, Structure

DT = 1e-6  # the record is taken at the analysis rate (sample_rate_hz=None: no resampling)
N = 4096
START_S, WIDTH_S = 300e-6, 20e-6
F_N_HZ, ZETA, GAIN = 27e3, 0.05, 2.5
SIGMA_U, SIGMA_Y = 2e-3, 2e-3  # white noise RMS, × each channel's peak


def sensor() -> signal.lti:
    wn = 2 * np.pi * F_N_HZ
    return signal.lti([GAIN * wn**2], [1.0, 2 * ZETA * wn, wn**2])


def channels(seed: int = 1, samples: int = N, extra_y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The noise-free half-sine, the sensor's answer (plus `extra_y`), then white noise."""
    t = np.arange(samples) * DT
    u0 = np.where((t >= START_S) & (t < START_S + WIDTH_S), np.sin(np.pi * (t - START_S) / WIDTH_S), 0.0)
    _, y0, _ = signal.lsim(sensor(), u0, t)
    if extra_y is not None:
        y0 = y0 + extra_y[:samples]
    rng = np.random.default_rng(seed)
    peak_y = float(np.max(np.abs(y0)))
    return u0 + SIGMA_U * rng.standard_normal(samples), y0 + SIGMA_Y * peak_y * rng.standard_normal(samples)


def record(**kwargs) -> Record:
    u, y = channels(**kwargs)
    return Record(DT, u, y)


def prepared(rec: Record, order: int | None = None):
    prep_rec = prepare_record(rec, None, 8, order, 32)
    setup = search_setup(prep_rec.prep.spectral, prep_rec.prep, 8, order, DT, remove_delay=True, max_delay=32,
                         patience=3, max_evaluations=60, significance=0.05)
    return prep_rec, setup


def mode_of(fit: OrderFit) -> tuple[float, float]:
    """(f_n Hz, ζ) of the fit's complex pole pair."""
    p = next(r for r in np.roots(fit.a) if r.imag > 0)
    s = np.log(p) / DT
    return abs(s) / (2 * np.pi), -s.real / abs(s)


# ------------------------------------------------------------------------------ prepare
def test_locate_pulse_finds_the_pulse_and_its_window():
    u, y = channels()
    activity = locate_pulse(u, y, DT, 32)
    assert abs(activity.pulse_start - START_S / DT) <= 2
    # the window holds the pulse and the ringing (27 kHz at ζ 0.05 decays e-fold in 118 µs)
    assert activity.start < START_S / DT and activity.end > (START_S + WIDTH_S + 300e-6) / DT
    assert not activity.truncated and not activity.cold_start


def test_prepare_record_removes_each_channels_baseline():
    u, y = channels()
    pre = prepare_record(Record(DT, u + 0.3, y - 0.2), None, 8, None, 32).preprocessing
    assert pre.reference_baseline == pytest.approx(0.3, abs=3 * SIGMA_U)
    assert pre.response_baseline == pytest.approx(-0.2, abs=0.01)


def test_a_response_leading_by_many_samples_is_realigned_and_the_model_keeps_the_lead():
    """The known sensor's response advanced by 12 samples (the channels' skew, or an
    interferometer's demodulation delaying the reference): `realigned` delays it by whole
    samples before the fit (the cross-correlation reads the lead ~8 samples short, by the
    ringing sensor's own lag, so by a few here), and the identified model, its delay included,
    is the truth advanced by 12 samples, within 1 % and 0.5° from 1 to 20 kHz (as recorded it
    was 80 % and 26° off: no structure reached the lead). A lead under 2 samples is left alone."""
    from hopkinson.analysis.identify import identify
    from hopkinson.analysis.response import frequency_response

    u, y = channels()
    as_recorded = Record(DT, u, y)
    same, nothing = realigned(as_recorded, 32)
    assert same is as_recorded and nothing == Alignment()  # the sensor's own lag: nothing to do
    rec = Record(DT, u, np.roll(y, -12))
    moved, alignment = realigned(rec, 32)
    shift = alignment.shift
    assert shift >= 1 and shift - 1 < alignment.lead <= shift and not alignment.not_taken
    # the reference whole (its lead-in with it); the response delayed, its head mirrored from its lead-in
    assert moved.start_time_s == 0.0 and np.array_equal(moved.reference, u)
    assert np.array_equal(moved.response[shift:], rec.response[: N - shift])
    assert np.array_equal(moved.response[:shift], rec.response[shift:0:-1])
    ident = identify(rec, sample_rate_hz=None)
    assert any(f"realigned by {shift} samples" in w for w in ident.warnings), ident.warnings
    f = np.linspace(1e3, 20e3, 20)
    model = frequency_response(ident.model, f) * np.exp(-2j * np.pi * f * DT * ident.model.delay_samples)
    _, truth = signal.freqresp(sensor(), 2 * np.pi * f)
    ratio = model / (truth * np.exp(2j * np.pi * f * DT * 12))
    assert np.max(np.abs(np.abs(ratio) - 1.0)) < 0.01 and np.max(np.abs(np.degrees(np.angle(ratio)))) < 0.5


def test_a_lead_the_responses_lead_in_cannot_cover_is_not_realigned_and_says_why():
    """A response leading by 8 samples whose pulse starts 2 samples into the record: its head
    cannot be mirrored from a lead-in it does not have, so the record is left as it is, and the
    lead not taken is named for the refusal or warning that follows; one at the search's edge
    says it may be larger."""
    t = np.arange(400)
    u = np.where((t >= 10) & (t < 30), np.sin(np.pi * (t - 10) / 20), 0.0)
    rec = Record(DT, u, 0.5 * np.roll(u, -8) + 1e-4 * np.random.default_rng(2).standard_normal(t.size))
    same, alignment = realigned(rec, 32)
    assert same is rec and alignment.shift == 0 and alignment.not_taken
    assert alignment.lead == pytest.approx(8.0, abs=0.1)
    assert "leads the reference by about 8 samples (8 µs)" in alignment.not_taken_text(DT)
    assert "too near the record's start" in alignment.not_taken_text(DT)
    assert "or more" in Alignment(lead=64.0, at_edge=True).not_taken_text(DT)
    assert Alignment(shift=9, lead=8.4).not_taken_text(DT) == ""


def test_locate_pulse_tells_a_record_cut_short():
    u, y = channels(samples=340)  # cut 20 µs after the pulse, the sensor still ringing
    assert locate_pulse(u, y, DT, 32).truncated


# ------------------------------------------------------------------------------ noise
def test_measure_noise_reads_the_known_levels():
    u, y = channels(seed=3)
    scale_y = float(np.max(np.abs(y)))
    noise = measure_noise(locate_pulse(u, y / scale_y, DT, 32), DT)
    assert noise.draw_noise_u.rms == pytest.approx(SIGMA_U, rel=0.15)
    # y's peak is the noise-free peak within a few σ of the noise
    assert noise.draw_noise_y.rms * scale_y == pytest.approx(SIGMA_Y * scale_y, rel=0.15)
    assert not noise.motion
    assert abs(noise.drift_lines["response"][0]) * N < 3 * SIGMA_Y  # no drift to speak of over the record


def test_measure_noise_leaves_coherent_motion_out():
    t = np.arange(N) * DT
    after = t > START_S + 700e-6
    # below the reference's busy level (2 % of the peak), as on PTB's record (1–2 %)
    motion = np.where(after, 0.009 * np.sin(2 * np.pi * 9e3 * t) + 0.006 * np.sin(2 * np.pi * 4.1e3 * t), 0.0)
    u, y = channels(seed=4)
    u, y = u + motion, y + motion * GAIN
    scale_y = float(np.max(np.abs(y)))
    noise = measure_noise(locate_pulse(u, y / scale_y, DT, 32), DT)
    # the stretch after the pulse starts with the sensor still ringing (12 % of the peak in the
    # response): judged whole it is not coherent, so the motion is found as its tail
    assert noise.motion, "the coherent motion after the pulse was taken as noise"
    onset = min(m["start_sample"] for m in noise.motion)
    # found once it dominates the tail: after the pulse, and no later than a step past its start
    assert (START_S + WIDTH_S) / DT < onset <= START_S / DT + 700 + 2 * 64
    # measured where the channels are at rest: the known white level, not the motion's (~0.8 %)
    assert noise.draw_noise_u.rms == pytest.approx(SIGMA_U, rel=0.2)


def test_measure_noise_leaves_out_a_short_stretch_while_the_other_channel_moves():
    """A record cut 0.4 ms after the pulse: the reference's stretch after it (~0.3 ms) is too short
    for its coherence to show weak motion, and the response has not come to rest over it; the
    bar's motion there is not the reference's noise (PTB's record cut to 1.2 ms read it at 12x)."""
    samples = 720
    t = np.arange(samples) * DT
    after = t > START_S + 100e-6
    motion = np.where(after, 0.009 * np.sin(2 * np.pi * 9e3 * t) + 0.006 * np.sin(2 * np.pi * 4.1e3 * t), 0.0)
    u, y = channels(seed=5, samples=samples)
    u, y = u + motion, y + motion * GAIN
    scale_y = float(np.max(np.abs(y)))
    activity = locate_pulse(u, y / scale_y, DT, 32)
    after_pulse = [r for r in activity.u_segments if r.start > 0]
    assert after_pulse and all(r.stop - r.start < 544 for r in after_pulse)  # the case: a short stretch
    noise = measure_noise(activity, DT)
    assert [m["reason"] for m in noise.motion] == ["too short to judge by coherence, the other channel not at rest"]
    assert noise.u_segments == [r for r in activity.u_segments if r.start == 0]
    # the lead-in's known white level, not the motion's (~0.6 % RMS)
    assert noise.draw_noise_u.rms == pytest.approx(SIGMA_U, rel=0.2)


def test_measure_noise_leaves_out_the_head_of_a_moving_stretch_while_the_sensor_rings():
    """The bar moves from the pulse on (a bonded sensor on PTB's record, the simulator's bonded
    bar shots), and the sensor rings (12 % of the peak) over the first part of the stretch after it: judged whole
    and in its first steps that part is not coherent, so the motion is found only as a later
    tail. The head before it is too short to judge on its own while the response is busy: not
    the reference's noise (it was: on the bonded shots 64 samples of flight and motion set the
    reference's noise in the band ~10⁴ times too high, and the model error went unseen)."""
    t = np.arange(N) * DT
    after = t > START_S + WIDTH_S
    motion = np.where(after, 0.009 * np.sin(2 * np.pi * 9e3 * t) + 0.006 * np.sin(2 * np.pi * 4.1e3 * t), 0.0)
    u0 = np.where((t >= START_S) & (t < START_S + WIDTH_S), np.sin(np.pi * (t - START_S) / WIDTH_S), 0.0)
    _, y0, _ = signal.lsim(sensor(), u0, t)
    rng = np.random.default_rng(6)
    peak_y = float(np.max(np.abs(y0)))
    u = u0 + motion + SIGMA_U * rng.standard_normal(N)
    y = y0 + motion * GAIN + SIGMA_Y * peak_y * rng.standard_normal(N)
    scale_y = float(np.max(np.abs(y)))
    activity = locate_pulse(u, y / scale_y, DT, 32)
    noise = measure_noise(activity, DT)
    found = [m for m in noise.motion if m["reason"] == "coherent"]
    assert found, "the coherent motion after the pulse was not found"
    after_pulse = [r for r in activity.u_segments if r.start > 0]
    assert after_pulse and min(m["start_sample"] for m in found) > after_pulse[0].start  # the case: a head
    assert noise.u_segments == [r for r in activity.u_segments if r.start == 0]
    # the head left out is in the trail (identify --explain), with why
    head = [m for m in noise.motion if m["coherence"] is None]
    assert [(m["start_sample"], m["stop_sample"]) for m in head] == [
        (after_pulse[0].start, min(m["start_sample"] for m in found))]
    assert head[0]["reason"] == "too short to judge by coherence, the other channel not at rest"
    assert noise.draw_noise_u.rms == pytest.approx(SIGMA_U, rel=0.2)


def test_measure_noise_leaves_out_a_short_head_where_weak_motion_has_begun():
    """Heavy noise (1 % of each peak) and motion from the pulse on, weak at first (0.6 % of the
    peak, then 1.5 % from 0.75 ms): the tail's coherence clears the threshold only once the strong
    part dominates it, at 0.71 ms. The ~0.3 ms head before it is too short for its own coherence to
    show the weak motion, and the well-damped response is at rest over it, so only this rule leaves
    it out; taken as quiet it held that motion, and the fit's look at the reference's noise read
    ×1.23 too high (PTB's
    record with 2 % of its peak of noise added: ×1.3-1.6, the band stopped at 20 kHz, and 4 of 20
    such records missed the sine calibration)."""
    samples, sigma, zeta = 1500, 1e-2, 0.2
    t = np.arange(samples) * DT
    end = START_S + WIDTH_S
    level = np.where(t > end, np.where(t < 750e-6, 0.4, 1.0), 0.0)
    motion = 0.015 * level * (0.6 * np.sin(2 * np.pi * 9e3 * t) + 0.4 * np.sin(2 * np.pi * 4.1e3 * t))
    wn = 2 * np.pi * F_N_HZ
    u0 = np.where((t >= START_S) & (t < end), np.sin(np.pi * (t - START_S) / WIDTH_S), 0.0)
    _, y0, _ = signal.lsim(signal.lti([GAIN * wn**2], [1.0, 2 * zeta * wn, wn**2]), u0, t)
    rng = np.random.default_rng(1)
    peak_y = float(np.max(np.abs(y0)))
    u = u0 + motion + sigma * rng.standard_normal(samples)
    y = y0 + motion * GAIN + sigma * peak_y * rng.standard_normal(samples)
    activity = locate_pulse(u, y / float(np.max(np.abs(y))), DT, 32)
    noise = measure_noise(activity, DT)
    after_pulse = [r for r in activity.u_segments if r.start > 0]
    found = [m for m in noise.motion if m["reason"] == "coherent" and m["start_sample"] > after_pulse[0].start]
    assert found, "the case: the motion found as a tail, after a head"
    onset = min(m["start_sample"] for m in found)
    assert 32 < onset - after_pulse[0].start < 544  # the head: long enough to use, too short to judge
    assert sum(max(0, min(onset, q.stop) - max(after_pulse[0].start, q.start)) for q in activity.y_segments) > (
        0.5 * (onset - after_pulse[0].start))  # the response at rest over it: not the `unjudged` rule
    assert noise.u_segments == [r for r in activity.u_segments if r.start == 0]
    assert {"start_sample": after_pulse[0].start, "stop_sample": onset, "coherence": None,
            "reason": "too short to judge by coherence, and the motion that follows may have begun in it"} in noise.motion
    # both looks at the reference's noise are the lead-in's known white level, not the motion's
    assert noise.noise_u.rms == pytest.approx(sigma, rel=0.1)
    assert noise.draw_noise_u.rms == pytest.approx(sigma, rel=0.1)


def test_the_lead_in_reaches_the_pulses_foot():
    """A capture started shortly before a long pulse (90 µs, 140 µs in) on a bar that keeps moving
    after it: the lead-in at rest is the 140 µs before the foot, less a guard of a quarter of the
    pulse's width, as the margins the window needs (twice the pulse's width and the delay) leave
    none. Until stop 37 it ended where they begin (the lead-in's end when they leave one): before
    the record's start, so there was no lead-in, and the reference's noise was measured on the
    motion (PTB's record started 0.2 ms later: ×11, the band cut to 20 kHz and the FBSD ±5 %
    interval missing the sine's edge)."""
    samples, start_s, base_s, sigma = 2000, 140e-6, 90e-6, 2e-3
    t = np.arange(samples) * DT
    u0 = np.where((t >= start_s) & (t < start_s + base_s), np.sin(np.pi * (t - start_s) / base_s), 0.0)
    motion = 0.02 * (t > start_s + base_s) * np.sin(2 * np.pi * 6e3 * t)
    _, y0, _ = signal.lsim(sensor(), u0 + motion, t)
    rng = np.random.default_rng(4)
    u = u0 + motion + sigma * rng.standard_normal(samples)
    y = (y0 + sigma * GAIN * rng.standard_normal(samples)) / GAIN
    activity = locate_pulse(u, y, DT, 32)
    lead = activity.u_segments[0]
    width = 60  # the half-sine's width at half its height, µs: 2/3 of its base
    assert lead.start == 0 and start_s / DT - width // 4 - 12 <= lead.stop <= start_s / DT
    assert activity.y_segments[0] == lead
    noise = measure_noise(activity, DT)
    assert not any("no lead-in at rest" in f.text for f in noise.findings)
    # both looks at the reference's noise are the known white level, not the motion's (0.014 RMS)
    assert noise.noise_u.rms == pytest.approx(sigma, rel=0.25)
    assert noise.draw_noise_u.rms == pytest.approx(sigma, rel=0.2)
    # the same shot captured 0.3 ms earlier: the margins leave a lead-in, and it ends there, clear of
    # the foot's rise below the noise
    early = locate_pulse(np.concatenate((sigma * rng.standard_normal(300), u)),
                         np.concatenate((sigma * rng.standard_normal(300), y)), DT, 32)
    assert early.u_segments[0].start == 0 and early.u_segments[0].stop <= 300 + start_s / DT - 2 * width - 32


def test_measure_noise_removes_a_drift_pinned_before_and_after_the_pulse():
    t = np.arange(N) * DT
    u, y = channels(seed=9)
    peak_y = float(np.max(np.abs(y)))
    slope_per_s = 20.0 * peak_y  # 2 % of the peak per ms
    y = y + slope_per_s * t
    scale_y = float(np.max(np.abs(y)))
    activity = locate_pulse(u, y / scale_y, DT, 32)
    noise = measure_noise(activity, DT)
    assert noise.drift_removed
    assert noise.drift_lines["response"][0] * scale_y / DT == pytest.approx(slope_per_s, rel=0.05)
    # the reference has no drift (its unit is its own: no scale was applied)
    assert noise.drift_lines["reference"][0] / DT == pytest.approx(0.0, abs=0.05 * slope_per_s / peak_y)


# ------------------------------------------------------------------------------ band
def test_fitted_band_crosses_the_pulses_nulls_and_weighs_each_bin_by_its_noise():
    """Issue 40 item 4: the band is every frequency the pulse supports, between its spectral nulls
    too. A half-sine of width w has its nulls at (k + 0.5)/w (k ≥ 1); its band runs past the first
    one, no fitted bin lies in a null (there |F| < 1 % of its maximum: within 0.2/w of the zero),
    and its first stretch ends before the first null (it stopped there before)."""
    u, y = channels(seed=5)
    activity = locate_pulse(u, y, DT, 32)
    prep = fitted_band(activity, measure_noise(activity, DT), DT)
    first_null_hz = 1.5 / WIDTH_S  # a half-sine of width w has its first spectral zero at 1.5/w
    assert prep.support.intervals_hz[0][1] < first_null_hz < prep.band[1]
    assert prep.band[1] >= 2.5 / WIDTH_S  # past its second null
    nulls = (np.arange(1, 12) + 0.5) / WIDTH_S
    distance = np.min(np.abs(prep.bin_hz[:, None] - nulls[None, :]), axis=1)
    assert np.all(distance > 0.02 / WIDTH_S)  # no bin in a null
    assert np.all(prep.support.contains(prep.bin_hz))
    # white noise of variance σ² gives E|DFT_k|² = N σ² at every bin (N: the window's length)
    assert np.median(prep.draw_var_u) == pytest.approx(prep.u.size * SIGMA_U**2, rel=0.3)


# ------------------------------------------------------------------------------ fit per order, order choice
@pytest.fixture(scope="module")
def clean():
    prep_rec, setup = prepared(record(seed=6))
    return prep_rec, setup, fit_orders(prep_rec.prep.spectral, Structure.FREE, setup)


def test_fit_orders_chooses_the_known_order_and_finds_its_mode(clean):
    _, _, sweep = clean
    assert sweep.structure == Structure.FREE and sweep.chosen == 2
    f_n, zeta = mode_of(sweep.fits[2])
    assert f_n == pytest.approx(F_N_HZ, rel=0.01)
    assert zeta == pytest.approx(ZETA, rel=0.15)
    assert sweep.costs[2] < sweep.costs[1]


def test_fit_structures_takes_the_all_pole_model_when_free_zeros_do_not_beat_it(clean):
    """The known sensor has no finite zeros: the all-pole model of order 2 (7 parameters) fits it
    as well as free zeros (9), so the order test between the two keeps the simpler, and its mode
    is the known one."""
    prep_rec, setup, _ = clean
    sweep = fit_structures(prep_rec.prep.spectral, setup)
    assert sweep.structure == Structure.ALL_POLE and sweep.chosen == 2 and "order test between the two" in sweep.why
    f_n, zeta = mode_of(sweep.fits[2])
    assert f_n == pytest.approx(F_N_HZ, rel=0.01)
    assert zeta == pytest.approx(ZETA, rel=0.15)


def test_of_two_structures_with_as_many_parameters_the_lower_cost_stands():
    """Free order 1 and all-pole order 2 both take 4 parameters (PTB's record with 2 % more noise,
    seed 5: V 23.8 against 10.5): no parameter for the order test to weigh, so the likelihood
    decides, either way; the free one stood by default until stop 37."""
    from types import SimpleNamespace

    from hopkinson.analysis.order_search import _all_pole_preferred

    def sweep(order: int, cost: float):
        fit = OrderFit(np.ones(order + 1), np.ones(1), 0.0, np.zeros(0), 0.0, cost, 4, 10, True, False)
        return SimpleNamespace(chosen=order, fits={order: fit})

    assert _all_pole_preferred(sweep(1, 23.8), sweep(2, 10.5), None, None)
    assert not _all_pole_preferred(sweep(1, 10.5), sweep(2, 23.8), None, None)


def test_fit_structures_keeps_free_zeros_where_the_sensor_has_one():
    """A sensor with a real zero at 12 kHz (a response rising ×2.4 by 27 kHz before its mode):
    the all-pole model cannot follow it and free zeros beat it beyond chance."""
    wn, wz = 2 * np.pi * F_N_HZ, 2 * np.pi * 12e3
    with_zero = signal.lti([GAIN * wn**2 / wz, GAIN * wn**2], [1.0, 2 * ZETA * wn, wn**2])
    t = np.arange(N) * DT
    u0 = np.where((t >= START_S) & (t < START_S + WIDTH_S), np.sin(np.pi * (t - START_S) / WIDTH_S), 0.0)
    _, y0, _ = signal.lsim(with_zero, u0, t)
    rng = np.random.default_rng(8)
    y = y0 + SIGMA_Y * float(np.max(np.abs(y0))) * rng.standard_normal(N)
    prep_rec, setup = prepared(Record(DT, u0 + SIGMA_U * rng.standard_normal(N), y))
    sweep = fit_structures(prep_rec.prep.spectral, setup)
    assert sweep.structure == Structure.FREE and not sweep.why
    assert not has_doublet(sweep.fits[sweep.chosen].a, sweep.fits[sweep.chosen].b)


def test_the_all_pole_structure_has_no_finite_zeros_and_a_pole_pair_at_least(clean):
    prep_rec, setup, _ = clean
    sweep = fit_orders(prep_rec.prep.spectral, Structure.ALL_POLE, setup)
    assert min(sweep.fits) == 2
    for n, fit in sweep.fits.items():
        shape = all_pole_numerator(n)
        np.testing.assert_allclose(fit.b / fit.b[0], shape / shape[0], rtol=1e-12)
    # a sensor with its mode inside the band is all-pole as well: the same mode
    assert mode_of(sweep.fits[sweep.chosen])[0] == pytest.approx(F_N_HZ, rel=0.01)


def test_settle_order_keeps_an_asked_order_and_says_the_data_support_fewer():
    prep_rec, setup = prepared(record(seed=7), order=4)
    sweep = fit_orders(prep_rec.prep.spectral, Structure.FREE, setup)
    settled = settle_order(sweep, prep_rec.prep.spectral, setup)
    assert (settled.order, settled.selection) == (4, "asked")
    assert [f.code for f in settled.findings] == [FindingCode.ASKED_ORDER_UNSUPPORTED]
    assert any("data support only order 2" in f.text for f in settled.findings)


def test_settle_order_refuses_a_sweep_with_no_stable_order(clean):
    prep_rec, setup, sweep = clean
    with pytest.raises(AnalysisError, match="no stable model"):
        settle_order(replace(sweep, chosen=None), prep_rec.prep.spectral, setup)


def test_best_delay_branch_keeps_the_lowest_cost(clean):
    prep_rec, setup, sweep = clean
    final, others = best_delay_branch(sweep, 2, prep_rec.prep.spectral, setup)
    assert all(final.cost <= other.cost for other in others)
    assert final.delay >= 0.0  # the free structure's delay is causal


# ------------------------------------------------------------------------------ model error
def test_model_error_is_found_where_a_second_drive_path_puts_it():
    t = np.arange(N) * DT
    # a 12 kHz ringing the reference does not drive, 200 µs after the pulse (≈ 3 % of the peak): no
    # linear model of the reference with a delay ≤ 32 µs can follow it
    late = START_S + 200e-6
    burst = np.where(t >= late, 0.03 * GAIN * np.sin(2 * np.pi * 12e3 * (t - late)) * np.exp(-(t - late) / 150e-6),
                     0.0)
    prep_rec, setup = prepared(record(seed=8, extra_y=burst))
    prep = prep_rec.prep
    weighed = weigh_model_error(prep_rec, search_orders(prep_rec, AnalysisOptions(max_order=8, significance=0.05)))
    model_error, data = weighed.model_error, weighed.data
    assert model_error.significant
    lo, hi = model_error.range_hz
    assert lo <= 12e3 <= hi
    assert data.var_y.sum() > prep.spectral.var_y.sum()  # weighed as an output error of its own


@pytest.mark.parametrize("exponent", [0.0, 0.5, 1.0])
def test_the_model_errors_drive_law_is_recovered_from_residual_powers(exponent):
    """Closed-form truth: each bin's residual power is a circular Gaussian's, of variance noise +
    c·(|U|²/mean)^β, with a pulse's spectrum (its nulls included) as |U|. Over 60 seeds the
    maximum-likelihood β is the true one in nearly all and its total is unbiased."""
    from hopkinson.analysis.model_error import drive_law_variance

    f = np.linspace(500.0, 60e3, 240)
    width_s = 100e-6  # a half-sine's spectrum: its first null at 1.5/width = 15 kHz
    u_power = np.abs(np.cos(np.pi * f * width_s) / (1.0 - (2.0 * f * width_s) ** 2)) ** 2 + 1e-6
    shape = (u_power / u_power.mean()) ** exponent
    truth = 1.0 * shape
    expected = np.full(f.size, 0.01)
    found, totals = [], []
    for seed in range(60):
        power = (expected + truth) * np.random.default_rng(seed).exponential(1.0, f.size)
        var, beta = drive_law_variance(power, expected, u_power)
        found.append(beta)
        totals.append(var.sum() / truth.sum())
    assert np.mean(np.isclose(found, exponent)) >= 0.9, np.unique(found, return_counts=True)  # measured: 60/60
    assert abs(np.median(found) - exponent) < 1e-9
    assert abs(np.mean(totals) - 1.0) < 3.0 * np.std(totals) / np.sqrt(len(totals)), np.mean(totals)


def test_no_model_error_is_claimed_on_a_record_the_model_explains(clean):
    prep_rec, setup, sweep = clean
    prep = prep_rec.prep
    error = measure_model_error(prep, prep.spectral, sweep.fits[2], sweep.parameters[2], DT)
    assert not error.significant and error.ratio < 2.0


# ------------------------------------------------------------------------------ claims
def pair(f_hz: float, zeta: float) -> np.ndarray:
    s = 2 * np.pi * f_hz * (-zeta + 1j * np.sqrt(1 - zeta**2))
    p = np.exp(s * DT)
    return np.array([p, p.conjugate()])


def test_claims_mark_a_doublet_and_keep_it_from_the_modes():
    poles = pair(17e3, 0.05)
    model = DiscreteModel(DT, np.real(np.poly(poles)), np.real(np.poly(poles * 1.001)), 0.0)
    modes = claimed_modes(model, (500.0, 28e3), Structure.FREE)
    (m,) = [m for m in modes if m["kind"] == "complex"]
    assert m["cancelled"] and not m["supported"]
    assert m["natural_frequency_hz"] == pytest.approx(17e3, rel=1e-6)


def test_claims_of_the_all_pole_structure_mark_a_resonance_beyond_the_band():
    a = np.real(np.poly(pair(55e3, 0.02)))
    model = DiscreteModel(DT, a, all_pole_numerator(2) * np.sum(a) / 1.0, 0.0)
    (m,) = claimed_modes(model, (500.0, 28e3), Structure.ALL_POLE)
    assert m["shapes_band"] and not m["supported"] and not m["cancelled"]
    (free,) = claimed_modes(model, (500.0, 28e3), Structure.FREE)
    assert "shapes_band" not in free


def test_a_negative_all_pole_delay_is_reported_as_a_lead():
    a = np.real(np.poly(pair(55e3, 0.02)))
    fit = OrderFit(a, all_pole_numerator(2), -0.35, np.zeros(0), 1.0, 1.0, 5, 2, True, False)
    (finding,) = delay_findings(None, fit, Structure.ALL_POLE, DT, 0.05)  # type: ignore[arg-type]
    assert finding.code == FindingCode.NEGATIVE_DELAY
    assert "leads the reference by 0.35 samples (0.35 µs)" in finding.text
    assert delay_findings(None, replace(fit, delay=0.1), Structure.ALL_POLE, DT, 0.05) == []  # type: ignore[arg-type]


def test_the_all_pole_structure_is_tried_when_free_zeros_claim_no_mode_and_cannot_go_higher(clean):
    from hopkinson.analysis.order_search import OrderSweep, _exhausted_without_mode

    _, setup, _ = clean
    real = OrderFit(np.array([1.0, -0.9]), np.array([0.1, 0.0]), 0.0, np.zeros(0), 0.0, 1.0, 4, 1, True, False)
    in_band = OrderFit(np.real(np.poly(pair(F_N_HZ, ZETA))), np.array([0.1, 0.0, 0.0]), 0.0, np.zeros(0), 0.0, 1.0,
                       6, 1, True, False)

    def sweep(fit: OrderFit, higher_cost: float) -> OrderSweep:
        n = fit.order
        return OrderSweep(Structure.FREE, DelayMode.CAUSAL, {n: fit}, {n: 2 * n + 2}, {n: 1.0, n + 1: higher_cost, n + 2: math.inf},
                          {}, n, None)

    assert _exhausted_without_mode(sweep(real, math.inf), setup)  # a real pole, every higher order unstable
    assert not _exhausted_without_mode(sweep(real, 0.9), setup)  # a higher order is a candidate
    assert not _exhausted_without_mode(sweep(in_band, math.inf), setup)  # a mode inside the band is claimed

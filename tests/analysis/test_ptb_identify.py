"""Issue 17: the default identification on PTB's real shock record, and on hybrids (the real
reference drives a known sensor, with a real-shaped disturbance injected): motion after the
pulse is not taken as noise, the model error is detected and carried into the intervals, and
the intervals contain the independent truth (the sine calibration's edges, the hybrid's model)."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from hopkinson.analysis.params import AnalysisParams
from hopkinson.analysis.records import Record
from hopkinson.analysis.shot_analysis import analyse_record
from scipy import signal

from tests.ptb_shock import SINE_FBSD_5_HZ, SINE_FBSD_10_HZ, against_sine, ptb_record, ptb_sine

DRAWS = 60


@pytest.fixture(scope="module")
def ptb():
    return analyse_record(ptb_record(), AnalysisParams(draws=DRAWS, seed=1))


def test_motion_after_the_pulse_is_not_taken_as_noise(ptb):
    noise = ptb.identification.noise
    assert noise["motion_after_pulse"], "the coherent motion after the pulse was not detected"
    peak = float(np.max(np.abs(ptb_record().reference)))
    # the lead-in's noise (~0.07 % of the peak), not the motion's (~0.8 %: 11.8× before issue 17)
    assert noise["reference_rms"] < 0.002 * peak


def test_the_model_error_is_detected_and_sized(ptb):
    error = ptb.identification.noise["model_error"]
    assert error["detected"]
    assert 0.25 < error["rms_percent_of_peak"] < 3.0  # issue 17 measured 1–2 % of the peak
    assert any("model error" in w for w in ptb.warnings)
    assert any(row["source"] == "model error" for row in ptb.uncertainty["budget"])


def test_the_intervals_contain_the_sine_calibration(ptb):
    fbsd = ptb.uncertainty["fbsd_hz"]
    for level, sine_hz in (("5", SINE_FBSD_5_HZ), ("10", SINE_FBSD_10_HZ)):
        lo, hi = fbsd[level]["interval"]
        assert lo <= sine_hz <= hi, (level, lo, hi)
    lo, hi = ptb.uncertainty["dc_gain"]["interval"]
    assert lo <= ptb_sine().magnitude[0] <= hi  # the 0.5 kHz point: the sensitivity


def test_the_intervals_are_as_narrow_as_the_issue_asks(ptb):
    fbsd = ptb.uncertainty["fbsd_hz"]
    for level in ("5", "10"):
        lo, hi = fbsd[level]["interval"]
        assert (hi - lo) / 2 <= 0.25 * fbsd[level]["value"]
    lo, hi = ptb.uncertainty["dc_gain"]["interval"]
    assert (hi - lo) / 2 <= 0.02 * ptb.uncertainty["dc_gain"]["value"]


def test_the_model_follows_the_sine_calibration(ptb):
    """The independent truth, the sine calibration (its own ripple ±1.7 %): the shock's model, an
    all-pole one whose resonance lies beyond the band, follows it. Before, the free structure's
    pole–zero doublet at 15 kHz was 6 % off below 20 kHz (issue 17)."""
    from hopkinson.analysis.sine_comparison import compare_sine

    assert ptb.identification.order_evidence["structure"] == "all_pole"
    comparison = compare_sine(ptb.model, ptb_sine())
    assert comparison.max_magnitude_error_below_pct(10e3) <= 1.5
    assert comparison.max_magnitude_error_below_pct(20e3) <= 3.5
    assert float(np.median(np.abs(comparison.magnitude_error_pct))) <= 0.5
    # the lead of the reference chain (PTB's response leads by ~0.35 µs) is fitted, not absorbed
    assert -1.0 < ptb.identification.delay_samples < 0.0
    assert any("fitted as a negative delay" in w for w in ptb.warnings)


def test_no_mode_is_claimed_inside_the_band(ptb):
    # the sine calibration shows none below 20 kHz (the resonance is near 51–57 kHz); issue 17's
    # 17 kHz "main mode" was a pole–zero doublet
    main = ptb.identification.main_mode
    assert main is None or main["natural_frequency_hz"] > 40e3
    for m in ptb.identification.modes:
        if m["kind"] == "complex" and m["natural_frequency_hz"] < 20e3:
            assert not m["supported"]


def test_intervals_stay_inside_physical_bounds(ptb):
    main = ptb.uncertainty["main_mode"]
    if main is not None:
        assert main["natural_frequency_hz"]["interval"][0] > 0
        assert main["damping_ratio"]["interval"][0] >= 0
    for e in ptb.uncertainty["fbsd_hz"].values():
        assert e["interval"][0] > 0


# ---------------------------------------------------------------------------- hybrids
F_N_HZ, ZETA, SENSITIVITY = 55e3, 0.03, 0.23  # a sensor like PTB's (sine: mode near 51–57 kHz)


def hybrid_record(tension: float = 1.0, compression: float = 1.0, seed: int = 5) -> tuple[Record, signal.lti]:
    """PTB's real reference (its pulse, its motion after the pulse, its noise) driving a known
    continuous sensor, each lobe of the pulse with its own gain (issue 17 measured ×0.993 in
    tension and ×1.0145 in compression), plus white noise at 0.01 % of the response's peak."""
    rec = ptb_record()
    wn = 2 * np.pi * F_N_HZ
    truth = signal.lti([SENSITIVITY * wn**2], [1.0, 2 * ZETA * wn, wn**2])
    ref = rec.reference
    drive = np.where(ref >= 0, tension, compression) * ref
    _, y, _ = signal.lsim(truth, drive, rec.time_s - rec.time_s[0])
    rng = np.random.default_rng(seed)
    y = y + rng.normal(0.0, 1e-4 * np.max(np.abs(y)), y.size)
    return Record(rec.sample_interval_s, ref, y, response_unit="pC"), truth


def truth_fbsd_hz(truth: signal.lti) -> dict[str, float]:
    f = np.linspace(100.0, 40e3, 4000)
    _, h = signal.freqresp(truth, 2 * np.pi * f)
    rel = np.abs(h) / SENSITIVITY
    return {"5": float(np.interp(1.05, rel, f)), "10": float(np.interp(1.10, rel, f))}


@pytest.fixture(scope="module")
def clean_hybrid():
    rec, truth = hybrid_record()
    return analyse_record(rec, AnalysisParams(draws=DRAWS, seed=2)), truth


def test_a_hybrid_with_the_real_reference_is_recovered(clean_hybrid):
    analysis, truth = clean_hybrid
    ident = analysis.identification
    assert ident.noise["motion_after_pulse"]  # the real reference's motion, seen by both channels
    assert not ident.noise["model_error"]["detected"]  # a linear sensor: nothing beyond the noise
    for level, edge in truth_fbsd_hz(truth).items():
        lo, hi = analysis.uncertainty["fbsd_hz"][level]["interval"]
        assert lo <= edge <= hi, (level, edge, lo, hi)
    lo, hi = analysis.uncertainty["dc_gain"]["interval"]
    assert lo <= SENSITIVITY <= hi
    assert_mode_between_the_nulls(analysis)


def assert_mode_between_the_nulls(analysis) -> None:
    """Issue 40 item 4: the 55 kHz mode lies between the pulse's spectral nulls (its stretches
    45.3-51.1 and 53.6-60.5 kHz, a null between): the band runs across the nulls, so the mode is
    claimed, within 0.5 % and inside its interval, and so is its damping (until issue 40 the band
    stopped at the first null, 28 kHz, and the mode was only bounded from below)."""
    ident, u = analysis.identification, analysis.uncertainty["main_mode"]
    assert ident.supported_band_hz[1] > F_N_HZ and len(ident.supported_band.intervals_hz) > 1
    main = ident.main_mode
    assert main is not None and abs(main["natural_frequency_hz"] / F_N_HZ - 1) < 0.005, main
    lo, hi = u["natural_frequency_hz"]["interval"]
    assert lo <= F_N_HZ <= hi, (lo, hi)
    lo, hi = u["damping_ratio"]["interval"]
    assert lo <= ZETA <= hi, (lo, hi)


# The sensitivity reported is the mean of both directions (analysis.input_terms), what PTB's sine
# calibration measures too; PTB's main pulse is positive, driven here at the hybrid's `tension` gain.
def mean_truth(tension: float, compression: float) -> float:
    return 0.5 * (tension + compression) * SENSITIVITY


def epsilon_truth(tension: float, compression: float) -> float:
    """ε = the other direction's gain ÷ the main direction's − 1."""
    return compression / tension - 1.0


@pytest.fixture(scope="module")
def lobe_hybrid():
    rec, truth = hybrid_record(tension=0.993, compression=1.0145, seed=1)
    return analyse_record(rec, AnalysisParams(draws=DRAWS, seed=2)), truth


def test_a_lobe_dependent_gain_is_measured_as_the_asymmetry(lobe_hybrid):
    """Issue 40 item 1: the gain that differs between the pulse's lobes (issue 17 measured ×0.993
    and ×1.0145 on PTB's record) is fitted as ε, inside its interval; the rest of the model is then
    what the sensor is, no model error is left, and its mode between the nulls is claimed. Until
    issue 40 it was weighed and drawn as model error (issue 17: before that, "no order gives a
    stable model")."""
    analysis, _ = lobe_hybrid
    ident = analysis.identification
    assert not ident.noise["model_error"]["detected"]
    epsilon = analysis.uncertainty["input_terms"]["asymmetry"]
    lo, hi = epsilon["interval"]
    assert lo <= epsilon_truth(0.993, 1.0145) <= hi and hi - lo < 0.02, epsilon
    assert_mode_between_the_nulls(analysis)


def test_a_lobe_dependent_gain_is_carried_into_the_intervals(lobe_hybrid):
    analysis, truth = lobe_hybrid
    for level, edge in truth_fbsd_hz(truth).items():
        lo, hi = analysis.uncertainty["fbsd_hz"][level]["interval"]
        assert lo <= edge <= hi, (level, edge, lo, hi)
    lo, hi = analysis.uncertainty["dc_gain"]["interval"]
    assert lo <= mean_truth(0.993, 1.0145) <= hi


@pytest.mark.parametrize("scale", [0.25, 2.0])
def test_a_weaker_or_stronger_lobe_dependent_gain_is_carried_into_the_intervals(scale):
    """A quarter of the measured gain asymmetry (the free fit's doublet at 12.7 kHz once took it in)
    and twice it: ε inside its interval, the mode between the nulls claimed, the FBSD edges and the
    sensitivity (the mean of both directions) inside theirs."""
    tension, compression = 1 - 0.007 * scale, 1 + 0.0145 * scale
    rec, truth = hybrid_record(tension=tension, compression=compression, seed=6)
    analysis = analyse_record(rec, AnalysisParams(draws=DRAWS, seed=4))
    lo, hi = analysis.uncertainty["input_terms"]["asymmetry"]["interval"]
    assert lo <= epsilon_truth(tension, compression) <= hi, (lo, hi)
    assert_mode_between_the_nulls(analysis)
    for level, edge in truth_fbsd_hz(truth).items():
        lo, hi = analysis.uncertainty["fbsd_hz"][level]["interval"]
        assert lo <= edge <= hi and (hi - lo) / 2 <= 0.25 * edge, (level, edge, lo, hi)
    lo, hi = analysis.uncertainty["dc_gain"]["interval"]
    assert lo <= mean_truth(tension, compression) <= hi


@pytest.fixture(scope="module")
def motion_hybrid():
    """The clean hybrid with the bar's motion after the pulse (from 0.7 ms) reaching the sensor
    at ×0.75 of what the reference sees (issue 17 measured ×0.75 on the real record)."""
    rec, truth = hybrid_record()
    after = rec.time_s - rec.time_s[0] >= 7.0e-4
    _, extra, _ = signal.lsim(truth, np.where(after, -0.25 * rec.reference, 0.0), rec.time_s - rec.time_s[0])
    moved = Record(rec.sample_interval_s, rec.reference, rec.response + extra, response_unit="pC")
    return analyse_record(moved, AnalysisParams(draws=DRAWS, seed=3)), truth


def test_motion_that_differs_between_the_channels_is_corrected_and_carried(motion_hybrid):
    """The sensor sees the bar's motion after 0.7 ms at ×0.75: the motion term (analysis.input_terms,
    from the pulse's end on) takes most of it (γ below zero), what it cannot follow is model error
    (not noise), and every interval holds the known sensor, its mode between the nulls included."""
    analysis, truth = motion_hybrid
    ident = analysis.identification
    assert ident.noise["model_error"]["detected"]
    lo, hi = analysis.uncertainty["input_terms"]["motion after the pulse"]["interval"]
    assert -0.25 < lo <= hi < 0.0, (lo, hi)
    for level, edge in truth_fbsd_hz(truth).items():
        lo, hi = analysis.uncertainty["fbsd_hz"][level]["interval"]
        assert lo <= edge <= hi, (level, edge, lo, hi)
    lo, hi = analysis.uncertainty["dc_gain"]["interval"]
    assert lo <= SENSITIVITY <= hi
    lo, hi = analysis.uncertainty["main_mode"]["natural_frequency_hz"]["interval"]
    assert lo <= F_N_HZ <= hi


@pytest.mark.parametrize("case", ["clean_hybrid", "motion_hybrid"])
def test_the_response_band_holds_the_known_sensor_throughout_the_band(case, request):
    analysis, truth = request.getfixturevalue(case)
    band = analysis.uncertainty["response_band"]
    f = np.array(band["frequency_hz"])
    _, h = signal.freqresp(truth, 2 * np.pi * f)
    relative = np.abs(h) / SENSITIVITY
    inside = f <= analysis.identification.supported_band_hz[1]
    low, high = np.array(band["magnitude_rel_low"]), np.array(band["magnitude_rel_high"])
    assert np.all((low[inside] <= relative[inside]) & (relative[inside] <= high[inside]))
    assert np.all(low <= np.array(band["magnitude_rel"])) and np.all(np.array(band["magnitude_rel"]) <= high)


def test_the_sine_points_are_judged_against_the_response_band(ptb):
    from hopkinson.analysis.sine_comparison import band_consistency, compare_sine

    sine = ptb_sine()
    judged = band_consistency(compare_sine(ptb.model, sine), ptb.uncertainty["response_band"])
    assert len(judged["e_n"]) == sine.frequency_hz.size
    assert judged["max_e_n"] == max(e for e in judged["e_n"] if e is not None)
    # the 0.5 kHz reference point: both normalised there, E_n 0
    assert judged["e_n"][0] < 1e-6


EN_SEEDS = range(1, 6)


@pytest.fixture(scope="module")
def sine_e_n():
    """The sine points judged against the response band, on each of EN_SEEDS, with the draws a
    user's analysis takes (400: the band's 2.5 % ends from 10 draws each, not 1.5 as at 60)."""
    from hopkinson.analysis.sine_comparison import band_consistency, compare_sine

    out = []
    for seed in EN_SEEDS:
        result = analyse_record(ptb_record(), AnalysisParams(seed=seed))
        out.append(band_consistency(compare_sine(result.model, ptb_sine()), result.uncertainty["response_band"]))
    return out


def sine_own_jumps(sine) -> np.ndarray:
    """The sine points their own neighbours contradict (one flag per point), judged on the sine
    data alone: off a quadratic through the three neighbours on each side by more than 3 of the
    point's stated u. A smooth sensor (its resonance beyond 50 kHz) cannot follow them, and no
    model's band should: they are where the sine's stated u understates its scatter."""
    f, m, u = sine.frequency_hz, sine.magnitude / sine.magnitude[0], sine.u_magnitude_rel
    out = np.zeros(f.size, dtype=bool)
    for k in range(f.size):
        near = [j for j in range(max(0, k - 3), min(f.size, k + 4)) if j != k]
        smooth = np.polyval(np.polyfit(f[near], m[near], 2), f[k])
        out[k] = abs(m[k] / smooth - 1.0) > 3.0 * u[k]
    return out


def test_the_sine_points_lie_near_the_response_band(sine_e_n):
    """E_n ≤ 0.5 at every sine point its neighbours agree with, on every seed; at the sine's own
    jumps (9.0–10.5, 14 and 18.5 kHz: 9.0 → 9.5 kHz +1.2 %, 10.0 → 10.5 kHz −0.9 %, 14 kHz +1.7 %
    off its neighbours, against a stated u of 0.15–0.25 %) at most 1. Measured: at most 0.39 at
    the agreeing points, 0.80–0.93 at the jumps (9.5 and 14 kHz). Until stop 38 the points' u
    left out the 0.5 % of the 500 Hz point they are normalised by (analysis.sine_comparison),
    and the jumps reached 1.49; 2.6 before the band's parts were drawn
    (analysis.uncertainty.BAND_TOPS)."""
    sine = ptb_sine()
    jumps = sine_own_jumps(sine)
    assert {9.5, 14.0} <= {round(f / 1e3, 1) for f in sine.frequency_hz[jumps]} and jumps.sum() <= 6
    for judged in sine_e_n:
        e_n = np.array([np.nan if e is None else e for e in judged["e_n"]])
        agree = ~jumps & np.isfinite(e_n)
        assert np.all(e_n[agree] <= 0.5), sine.frequency_hz[agree][e_n[agree] > 0.5]
        assert np.all(e_n[jumps] <= 1.0), e_n[jumps]


def test_the_sine_points_lie_inside_the_response_band(sine_e_n):
    """Issue 17 item 3: E_n ≤ 1 at every sine point, on every seed."""
    assert all(judged["consistent"] for judged in sine_e_n)
    assert all(judged["max_e_n"] <= 1.0 for judged in sine_e_n)


def test_identify_explain_prints_the_trail_on_the_real_record(tmp_path, capsys):
    from hopkinson.rig.cli.main import main

    from tests.ptb_shock import write_ptb_record_csv

    record = write_ptb_record_csv(tmp_path / "ptb.csv")
    assert main(["identify", str(record), "--no-uncertainty", "--explain"]) == 0
    out = capsys.readouterr().out
    trail = out[out.index("how this identification was decided:"):]
    assert "motion, not noise:" in trail  # the stretch after the pulse, left out of the noise
    assert "band:" in trail and "V by order:" in trail
    assert "model error: the residual is" in trail
    assert "claimed (inside the band)" not in trail  # nothing below 28 kHz is a mode


def test_motion_is_told_from_noise_by_its_coherence():
    from hopkinson.analysis.noise import is_motion

    rng = np.random.default_rng(11)
    rate, n = 1e6, 800
    t = np.arange(n) / rate
    # independent noise in each channel (an interferometer in flight, the sensor's amplifier)
    assert not is_motion(rng.standard_normal(n), rng.standard_normal(n), rate)[0]
    # the bar's motion at a few kHz seen by both (the sensor at x0.75), each with its own noise
    motion = np.sin(2 * np.pi * 3e3 * t) + 0.5 * np.sin(2 * np.pi * 11e3 * t + 1.0)
    moving, coherence = is_motion(motion + 0.3 * rng.standard_normal(n),
                                  0.75 * motion + 0.3 * rng.standard_normal(n), rate)
    assert moving and coherence > 0.5
    # too short to judge: never called motion
    assert not is_motion(motion[:100], motion[:100], rate)[0]


def test_a_pole_nearly_cancelled_by_a_zero_is_no_mode():
    from hopkinson.analysis.modes import main_mode, mark_doublets, modes_of

    dt = 1e-6
    pole = np.exp((-0.05 + 1j) * 2 * np.pi * 17e3 * dt)  # ζ 0.05 at 17 kHz: 1 − |p| ≈ 5.3e-3
    modes = modes_of(np.array([pole, pole.conjugate()]), dt, (0.0, 28e3))
    near = mark_doublets(modes, np.array([pole * 1.001, np.conj(pole) * 1.001]))  # 1e-3 away
    far = mark_doublets(modes, np.array([0.5, -0.3]))
    assert near[0]["cancelled"] and not near[0]["supported"] and main_mode(near) is None
    assert not far[0]["cancelled"] and main_mode(far)["natural_frequency_hz"] > 16e3


def test_identify_explain_gives_each_left_out_stretch_its_own_reason():
    """The trail says why each stretch after the pulse was left out of the noise, as the noise
    stage recorded it (a head before motion and a short stretch beside a busy channel differ)."""
    from hopkinson.rig.cli.identify import explain

    head = "too short to judge by coherence, and the motion that follows may have begun in it"
    beside = "too short to judge by coherence, the other channel not at rest"
    trail = explain({"noise": {"motion_after_pulse": [
        {"start_s": 1.188e-3, "stop_s": 1.8e-3, "coherence": 0.29, "reason": "coherent"},
        {"start_s": 0.868e-3, "stop_s": 1.188e-3, "coherence": None, "reason": head},
        {"start_s": 0.2e-3, "stop_s": 0.3e-3, "coherence": None, "reason": beside}]}})
    assert "1.188–1.8 ms moves coherently in both channels (power-weighted coherence 0.29)" in trail
    assert f"0.868–1.188 ms {head}: left out of the noise" in trail
    assert f"0.2–0.3 ms {beside}: left out of the noise" in trail


def test_identify_explain_tells_where_the_lead_in_ends(tmp_path, capsys):
    """The trail says where the noise's lead-in at rest ends and why: at the window's margin on the
    record as published (more than three of the pulse's widths at half height before its foot);
    within one such width before the foot on a capture started 0.2 ms later (the margins leave
    none); none at all on one
    started 0.33 ms later, where the bar's motion is measured as noise all the same, and no
    warning claims it was left out. The foot and the width are read here from the raw 10 MS/s
    record: where either channel's 50-sample mean |x| first stands 4 lead-in σ above its baseline,
    and the reference's span above half its peak."""
    from hopkinson.rig.cli.main import main

    from tests.ptb_shock import started_late, write_ptb_record_csv

    rec = ptb_record()
    dt = rec.sample_interval_s

    def rises(x: np.ndarray) -> int:
        quiet = x[:2000]
        level = np.convolve(np.abs(x - np.median(quiet)), np.full(50, 1 / 50), mode="same")
        return int(np.argmax(level > 4 * np.std(quiet)))

    foot_s = min(rises(rec.reference), rises(rec.response)) * dt
    width_s = np.count_nonzero(rec.reference > 0.5 * np.max(rec.reference)) * dt

    def lead_in_ms(record, name: str) -> tuple[str, float]:
        assert main(["identify", str(write_ptb_record_csv(tmp_path / f"{name}.csv", record)), "--no-uncertainty",
                     "--explain"]) == 0
        out = capsys.readouterr().out
        found = re.search(r"lead-in at rest: 0–([0-9.]+) ms", out)
        return out, float(found.group(1)) if found else math.nan

    published, stop_ms = lead_in_ms(rec, "ptb")
    assert "(to the window's margin before the pulse)" in published
    assert stop_ms * 1e-3 <= foot_s - 3 * width_s
    late, stop_ms = lead_in_ms(started_late(2_000), "late")
    assert "(to a quarter of the pulse's width before its foot" in late and "motion, not noise:" in late
    assert foot_s - 0.2e-3 - width_s <= stop_ms * 1e-3 < foot_s - 0.2e-3
    gone, _ = lead_in_ms(started_late(3_300), "gone")
    assert "lead-in at rest: none" in gone and "no lead-in at rest: its noise is measured on that motion" in gone
    assert "motion, not noise:" not in gone and "measured as noise all the same" in gone
    assert "that motion is not taken as noise" not in gone


def test_a_response_that_leads_by_microseconds_is_realigned_and_its_lead_kept(ptb):
    """PTB's response shifted 10 µs earlier (a deskew or trigger error, or the delay of an
    interferometer's demodulation): no sensor answers before it is excited and, as recorded, no
    model followed it (every fit unstable, refused until stop 38). It is realigned by whole
    samples before the fit and the lead kept in the model's delay. The truth is the shift made:
    the model, its delay draws and the joint fit's skew move by exactly 10 µs against the
    published record's; the intervals hold the sine's; the warning names the lead."""
    from hopkinson.analysis.identify import identify_with_sine
    from hopkinson.rig.cli.identify import explain

    from tests.ptb_shock import skewed

    shifted = analyse_record(skewed(-100), AnalysisParams(draws=DRAWS, seed=1))
    warning = next(w for w in shifted.warnings if "realigned" in w)
    lead = re.search(r"the response leads the reference by about [0-9.]+ samples \(([0-9.]+) µs\)", warning)
    assert lead and 9.0 <= float(lead.group(1)) <= 10.5
    # whole samples covering the 10 µs shift less the sensor's own lag, at most one more
    shift = int(re.search(r"realigned by (\d+) samples", warning).group(1))
    assert 10 <= shift <= 11
    dt = shifted.model.sample_interval_s
    assert shifted.model.delay_samples * dt == pytest.approx(ptb.model.delay_samples * dt - 10e-6, abs=0.05e-6)
    delay, published = shifted.uncertainty["delay_s"], ptb.uncertainty["delay_s"]
    assert np.allclose(delay["interval"], np.array(published["interval"]) - 10e-6, atol=0.2e-6)
    judged = against_sine(shifted.uncertainty)
    assert all(j["contains"] and j["half_width_ok"] for j in judged.values()), judged
    trail = explain(shifted.identification.to_dict())
    assert f"realigned: the response delayed by {shift} samples before the fit" in trail
    skews = [identify_with_sine(rec, ptb_sine()).sine_joint.skew_s for rec in (skewed(-100), ptb_record())]
    assert skews[0] == pytest.approx(skews[1] - 10e-6, abs=0.1e-6)


def test_a_lead_beyond_the_realignments_search_is_refused_with_its_cause(tmp_path, capsys):
    """PTB's response shifted 70 µs earlier, beyond the 64 samples realignment searches: every fit
    is unstable, and the refusal says the channels' cross-correlation peaked at its search's edge
    and what to do (until stop 38 it named no cause); one line naming the file, exit code 2."""
    from hopkinson.rig.cli.main import main

    from tests.ptb_shock import skewed, write_ptb_record_csv

    path = write_ptb_record_csv(tmp_path / "skewed.csv", skewed(-700))
    assert main(["identify", str(path), "--no-uncertainty"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "skewed.csv" in err and "Traceback" not in err
    assert "peaks at the edge of its search, a lead of 64 samples" in err and "correct the skew" in err


def test_a_table_file_whose_response_is_clipped_is_warned_about(tmp_path, capsys):
    """A table file carries no digitizer full scale, so a clipped channel went through unnoticed:
    PTB's response clipped at 90 % of its peak gave FBSD intervals too wide and a sensitivity's
    that misses the sine's (−1.8 % [−3.6, −0.6]), with no warning. `identify` now warns, by
    either method, of a clip at 97 % already (the clip is the truth: made here), and not of the
    same record quantised in 12 bits over 1.25× or in 8 bits over 4× its peak, whose extreme
    code repeats too."""
    from hopkinson.rig.cli.main import main

    from tests.ptb_shock import write_ptb_record_csv

    rec = ptb_record()

    def quantised(x: np.ndarray, bits: int, span: float) -> np.ndarray:
        step = 2 * span / 2**bits
        return np.round(x / step) * step

    top = 0.97 * float(np.max(np.abs(rec.response)))
    cases = {
        "clipped": (Record(rec.sample_interval_s, rec.reference, np.clip(rec.response, -top, top)), True),
        "published": (rec, False),
        "12bit": (Record(rec.sample_interval_s, *(quantised(x, 12, 1.25 * np.max(np.abs(x)))
                                                  for x in (rec.reference, rec.response))), False),
        "8bit": (Record(rec.sample_interval_s, *(quantised(x, 8, 4 * np.max(np.abs(x)))
                                                 for x in (rec.reference, rec.response))), False),
    }
    for name, (record, clipped) in cases.items():
        path = write_ptb_record_csv(tmp_path / f"{name}.csv", record)
        assert main(["identify", str(path), "--no-uncertainty", "--method", "paper"]) == 0
        out = capsys.readouterr().out
        assert ("response channel holds its extreme value" in out and "is it clipped?" in out) == clipped, name
        assert "reference channel holds its extreme value" not in out, name
    assert main(["identify", str(tmp_path / "clipped.csv"), "--no-uncertainty", "--json"]) == 0
    warnings = json.loads(capsys.readouterr().out)["warnings"]
    assert any("response channel holds its extreme value" in w for w in warnings), warnings

"""Issue 17: the default identification on PTB's real shock record: motion after the pulse is
not taken as noise, the model error is detected and carried into the intervals, the intervals
contain the independent truth (the sine calibration's edges and sensitivity) and the sine points
lie in the response band; `identify --explain` tells how; unit tests of the noise's motion test
and the modes' doublets; a response that leads, and a clipped one. The hybrids (the real
reference driving a known sensor) are test_ptb_hybrids.py's.

Seeds not picked to pass (issue 45 item 3). The record is identified once per session
(tests/analysis/ptb_fixtures.py) and its Monte Carlo drawn on seeds fixed before any result was
seen; containment is counted over them with a stated threshold, whose pass probabilities
(scipy.stats.binom) `test_the_thresholds_have_the_stated_power` asserts, for the hybrids'
threshold too (test_ptb_hybrids.py's module docstring):

- PTB's record: the sine's FBSD ±5 %, ±10 % and sensitivity in their intervals on each of the
  EN_SEEDS (400 draws, a user's analysis): 15 trials, at most PTB_MAX_MISSES = 2 misses.
  P(pass | 95 %) = 0.964; P(pass | 90 %) = 0.816, P(pass | 70 %) = 0.127. One record: the seeds
  vary only the Monte Carlo, not the data, so no seed count turns this into a coverage test;
  it shows the holding is no accident of one seed. The variants (test_ptb_variants.py) and the
  simulated studies (test_coverage_realistic.py) count coverage over data.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from scipy.stats import binom

from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.records import Record
from tests.analysis.ptb_fixtures import seeds
from tests.analysis.ptb_hybrids import HYBRID_MAX_MISSES, HYBRID_SEEDS, HYBRIDS, hybrid_figures
from tests.ptb_shock import against_sine, ptb_record, ptb_sine
from tests.studies.binomial import max_misses

DRAWS = 60
USER_DRAWS = AnalysisOptions().draws  # what a user's analysis takes (400)
EN_SEEDS = seeds(1, 5)
PTB_MAX_MISSES = 2


@pytest.fixture(scope="module")
def ptb(analyses):
    return analyses.analysed("ptb", ptb_record, seed=1, draws=DRAWS)


@pytest.fixture(scope="module")
def ptb_seeds(analyses):
    """PTB's record on each of EN_SEEDS with a user's draws (the band's 2.5 % ends from 10 draws
    each, not 1.5 as at 60)."""
    return [analyses.analysed("ptb", ptb_record, seed=seed, draws=USER_DRAWS) for seed in EN_SEEDS]


def test_the_thresholds_have_the_stated_power() -> None:
    trials = 3 * len(EN_SEEDS)
    assert binom.cdf(PTB_MAX_MISSES, trials, 0.05) >= 0.95  # 0.964
    assert binom.cdf(PTB_MAX_MISSES, trials, 0.30) <= 0.13  # 0.127 at 70 %
    trials = len(HYBRID_SEEDS) * sum(len(hybrid_figures(HYBRIDS[case][1])) for case in HYBRIDS)
    assert trials == 99
    assert HYBRID_MAX_MISSES == max_misses(trials)
    assert binom.cdf(HYBRID_MAX_MISSES, trials, 0.10) <= 0.05  # 0.025 at 90 % (trials taken as independent)
    assert binom.cdf(HYBRID_MAX_MISSES, trials, 0.01) >= 0.99  # 0.997 at 99 %


def test_motion_after_the_pulse_is_not_taken_as_noise(ptb):
    """The reference's noise is the lead-in's at rest (before the pulse), not the bar's motion
    after it (11.8× before issue 17): on a log scale it lies nearer the lead-in's standard
    deviation than the motion's, both read here from the record itself."""
    noise = ptb.identification.noise
    assert noise.motion_after_pulse, "the coherent motion after the pulse was not detected"
    rec = ptb_record()
    t = rec.time_s - rec.time_s[0]
    lead_in = float(np.std(rec.reference[t < 0.2e-3]))  # before the pulse's foot (beyond 0.3 ms)
    motion = float(np.std(rec.reference[t >= 1.0e-3]))  # the pulse over, the bar still moving
    assert abs(math.log(noise.reference_rms / lead_in)) < abs(math.log(noise.reference_rms / motion))


def test_the_model_error_is_detected_and_sized(ptb):
    error = ptb.identification.noise.model_error.to_dict()
    assert error["detected"]
    assert 0.25 < error["rms_percent_of_peak"] < 3.0  # issue 17 measured 1–2 % of the peak
    assert any("model error" in w for w in ptb.warnings)
    assert any(row["source"] == "model error" for row in ptb.uncertainty["budget"])


def test_the_intervals_contain_the_sine_calibration(ptb_seeds):
    """The sine's FBSD edges and its 0.5 kHz point (the sensitivity), on each seed: at most
    PTB_MAX_MISSES misses of 15 (module docstring)."""
    misses = [(seed, figure, j["interval"], j["truth"]) for seed, analysis in zip(EN_SEEDS, ptb_seeds, strict=True)
              for figure, j in against_sine(analysis.uncertainty).items() if not j["contains"]]
    assert len(misses) <= PTB_MAX_MISSES, misses


def test_the_intervals_are_as_narrow_as_the_issue_asks(ptb_seeds):
    """Issue 17's half-widths (FBSD 25 %, sensitivity 2 %) on every seed."""
    for analysis in ptb_seeds:
        assert all(j["half_width_ok"] for j in against_sine(analysis.uncertainty).values()), analysis.uncertainty


def test_the_model_follows_the_sine_calibration(ptb):
    """The independent truth, the sine calibration: the shock's model, an all-pole one whose
    resonance lies beyond the band, follows it at every point within the point's expanded
    uncertainty (k = 2, the 0.5 kHz point's 0.5 % in it: both are normalised there) plus the
    point's own distance from its neighbours' quadratic (up to 1.7 %: scatter no smooth response
    follows). Before, the free structure's pole–zero doublet at 15 kHz was 6 % off below 20 kHz
    (issue 17)."""
    from hopkinson.analysis.sine_comparison import compare_sine

    assert ptb.identification.order_evidence.structure == "all_pole"
    sine = ptb_sine()
    comparison = compare_sine(ptb.model, sine)
    u = np.hypot(sine.u_magnitude_rel, sine.u_magnitude_rel[0])
    u[0] = 0.0  # the normalisation point itself
    allowed_pct = 100.0 * (2.0 * u + sine_off_its_neighbours(sine))
    error_pct = np.abs(comparison.magnitude_error_pct)
    assert np.all(error_pct <= allowed_pct), sine.frequency_hz[error_pct > allowed_pct]
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
    """PTB's record claims no mode (its resonance lies beyond the band), so it carries no f_n or ζ
    interval: those bounds are checked on the hybrids, whose mode is claimed."""
    assert ptb.uncertainty["main_mode"] is None
    for e in ptb.uncertainty["fbsd_hz"].values():
        assert e["interval"][0] > 0

def test_the_sine_points_are_judged_against_the_response_band(ptb):
    from hopkinson.analysis.sine_comparison import band_consistency, compare_sine

    sine = ptb_sine()
    judged = band_consistency(compare_sine(ptb.model, sine), ptb.uncertainty["response_band"])
    assert len(judged["e_n"]) == sine.frequency_hz.size
    assert judged["max_e_n"] == max(e for e in judged["e_n"] if e is not None)
    # the 0.5 kHz reference point: both normalised there, E_n 0
    assert judged["e_n"][0] < 1e-6


@pytest.fixture(scope="module")
def sine_e_n(ptb_seeds):
    """The sine points judged against the response band, on each of EN_SEEDS, with the draws a
    user's analysis takes."""
    from hopkinson.analysis.sine_comparison import band_consistency, compare_sine

    return [band_consistency(compare_sine(result.model, ptb_sine()), result.uncertainty["response_band"])
            for result in ptb_seeds]


def sine_off_its_neighbours(sine) -> np.ndarray:
    """Each sine point's relative distance from a quadratic through its three neighbours on each
    side (normalised at the 0.5 kHz point), judged on the sine data alone."""
    f, m = sine.frequency_hz, sine.magnitude / sine.magnitude[0]
    out = np.zeros(f.size)
    for k in range(f.size):
        near = [j for j in range(max(0, k - 3), min(f.size, k + 4)) if j != k]
        out[k] = abs(m[k] / np.polyval(np.polyfit(f[near], m[near], 2), f[k]) - 1.0)
    return out


def sine_own_jumps(sine) -> np.ndarray:
    """The sine points their own neighbours contradict (one flag per point): off their
    neighbours' quadratic by more than 3 of the point's stated u. A smooth sensor (its resonance
    beyond 50 kHz) cannot follow them, and no model's band should: they are where the sine's
    stated u understates its scatter."""
    return sine_off_its_neighbours(sine) > 3.0 * sine.u_magnitude_rel


def test_the_sine_points_lie_near_the_response_band(sine_e_n):
    """The sine's own jumps, found on the sine data alone, include 9.5 and 14 kHz (9.0 → 9.5 kHz
    +1.2 %, 14 kHz +1.7 % off its neighbours, against a stated u of 0.15–0.25 %). A smooth sensor
    cannot follow them, so on every seed the largest E_n is at one of them: the points the sine's
    neighbours agree with lie nearer the band than the points they contradict. (Measured: at most
    0.39 at the agreeing points, 0.80–0.93 at the jumps; until stop 38 the points' u left out the
    0.5 % of the 500 Hz point they are normalised by, and the jumps reached 1.49.)"""
    sine = ptb_sine()
    jumps = sine_own_jumps(sine)
    assert {9.5, 14.0} <= {round(f / 1e3, 1) for f in sine.frequency_hz[jumps]} and jumps.sum() <= 6
    for judged in sine_e_n:
        e_n = np.array([np.nan if e is None else e for e in judged["e_n"]])
        agree = ~jumps & np.isfinite(e_n)
        assert np.max(e_n[agree]) < np.nanmax(e_n[jumps]), (e_n[agree], e_n[jumps])


def test_the_sine_points_lie_inside_the_response_band(sine_e_n):
    """Issue 17 item 3: E_n ≤ 1 (agreement at k = 2, by definition) at every sine point, on every seed."""
    assert all(judged["consistent"] for judged in sine_e_n)
    assert all(judged["max_e_n"] <= 1.0 for judged in sine_e_n)


_EXPLAINED: dict[str, str] = {}


def explained(tmp_path, capsys, name: str, record: Record | None = None) -> str:
    """What `identify FILE --no-uncertainty --explain` prints for `record` (PTB's: None) written as
    the interchange CSV; run once per name in the module."""
    from hopkinson.rig.cli.main import main
    from tests.ptb_shock import write_ptb_record_csv

    if name not in _EXPLAINED:
        path = write_ptb_record_csv(tmp_path / f"{name}.csv", record)
        assert main(["identify", str(path), "--no-uncertainty", "--explain"]) == 0
        _EXPLAINED[name] = capsys.readouterr().out
    return _EXPLAINED[name]


def test_identify_explain_prints_the_trail_on_the_real_record(tmp_path, capsys):
    out = explained(tmp_path, capsys, "ptb")
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


def test_a_real_pole_nearly_cancelled_by_a_zero_is_a_doublet_only_when_asked():
    """modes.has_doublet's `real`: order 2 plus a real pole at 250 Hz (1 − p ≈ 1.6e-3) with a zero
    2e-4 from it is a doublet (the draws leave such an order out); a zero 5e-3 away, or a real
    pole alone, is none; without `real` (identify's own rule) only a complex pair is judged."""
    from hopkinson.analysis.modes import has_doublet

    pair = np.exp((-0.03 + 1j) * 2 * np.pi * 55e3 * 1e-6)
    p = np.exp(-2 * np.pi * 250.0 * 1e-6)
    a = np.poly([pair, pair.conjugate(), p]).real
    near, far = np.poly([-0.5, p + 2e-4]).real, np.poly([-0.5, p - 5e-3]).real
    assert has_doublet(a, near, real=True) and not has_doublet(a, near)
    assert not has_doublet(a, far, real=True)
    assert not has_doublet(np.poly([pair, pair.conjugate()]).real, np.poly([-0.5, p]).real, real=True)


def test_identify_explain_gives_each_left_out_stretch_its_own_reason():
    """The trail says why each stretch after the pulse was left out of the noise, as the noise
    stage recorded it (a head before motion and a short stretch beside a busy channel differ)."""
    from hopkinson.analysis.trail import Stretch, motion_lines

    head = "too short to judge by coherence, and the motion that follows may have begun in it"
    beside = "too short to judge by coherence, the other channel not at rest"
    lines = motion_lines([Stretch(1.188e-3, 1.8e-3, 0.29, "coherent"), Stretch(0.868e-3, 1.188e-3, None, head),
                          Stretch(0.2e-3, 0.3e-3, None, beside)], kept=False)
    assert len(lines) == 3 and all(line.startswith("motion, not noise: ") for line in lines)
    trail = "\n".join(lines)
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

    from tests.ptb_shock import started_late

    rec = ptb_record()
    dt = rec.sample_interval_s

    def rises(x: np.ndarray) -> int:
        quiet = x[:2000]
        level = np.convolve(np.abs(x - np.median(quiet)), np.full(50, 1 / 50), mode="same")
        return int(np.argmax(level > 4 * np.std(quiet)))

    foot_s = min(rises(rec.reference), rises(rec.response)) * dt
    width_s = np.count_nonzero(rec.reference > 0.5 * np.max(rec.reference)) * dt

    def lead_in_ms(record, name: str) -> tuple[str, float]:
        out = explained(tmp_path, capsys, name, record)
        found = re.search(r"lead-in at rest: 0–([0-9.]+) ms", out)
        return out, float(found.group(1)) if found else math.nan

    published, stop_ms = lead_in_ms(None, "ptb")
    assert "(to the window's margin before the pulse)" in published
    assert stop_ms * 1e-3 <= foot_s - 3 * width_s
    late, stop_ms = lead_in_ms(started_late(2_000), "late")
    assert "(to a quarter of the pulse's width before its foot" in late and "motion, not noise:" in late
    assert foot_s - 0.2e-3 - width_s <= stop_ms * 1e-3 < foot_s - 0.2e-3
    gone, _ = lead_in_ms(started_late(3_300), "gone")
    assert "lead-in at rest: none" in gone and "no lead-in at rest: its noise is measured on that motion" in gone
    assert "motion, not noise:" not in gone and "measured as noise all the same" in gone
    assert "that motion is not taken as noise" not in gone


def test_a_response_that_leads_by_microseconds_is_realigned_and_its_lead_kept(ptb, analyses):
    """PTB's response shifted 10 µs earlier (a deskew or trigger error, or the delay of an
    interferometer's demodulation): no sensor answers before it is excited and, as recorded, no
    model followed it (every fit unstable, refused until stop 38). It is realigned by whole
    samples before the fit and the lead kept in the model's delay. The truth is the shift made:
    the model, its delay draws and the joint fit's skew move by exactly 10 µs against the
    published record's; the intervals hold the sine's; the warning names the lead."""
    from hopkinson.analysis.identify import identify_with_sine
    from hopkinson.analysis.trail import Stage
    from tests.ptb_shock import skewed

    shifted = analyses.analysed("ptb skewed -100", lambda: skewed(-100), seed=1, draws=DRAWS)
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
    trail = shifted.identification.trail.text()
    assert f"realigned: the response delayed by {shift} samples before the fit" in trail
    assert any(line.startswith(f"realigned: the response delayed by {shift} samples")
               for line in shifted.identification.trail.of(Stage.PREPARE))
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

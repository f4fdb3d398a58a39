"""analysis.dcm_design: the DCM designed only from what a shot supports, the honest automatic
ratio, the band limit and the noise-gain bound, against closed forms and constructed models."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import signal

from hopkinson.analysis.dcm_design import (
    ShotSupport,
    band_limit_fir,
    choose_poles,
    design_compensation,
)
from hopkinson.analysis.dcm_figures import compensated_fbsd_hz
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.response import fbsd_hz, response_times_samples

DT = 1e-6


def pair(fn_hz: float, zeta: float, dt: float = DT) -> np.ndarray:
    s = 2 * np.pi * fn_hz * (-zeta + 1j * math.sqrt(1 - zeta**2))
    return np.exp(np.array([s, np.conj(s)]) * dt)


def model_of(poles: np.ndarray, zeros: np.ndarray | None = None) -> DiscreteModel:
    """Unit-DC-gain model with these poles and zeros (b in powers of z⁻¹, causal)."""
    a = np.real(np.poly(poles))
    num = np.real(np.poly(zeros)) if zeros is not None and zeros.size else np.array([1.0])
    b = np.concatenate([np.zeros(a.size - num.size), num])
    return DiscreteModel(DT, a, b * np.sum(a) / np.sum(b))


def mode(p: complex, supported: bool = True) -> dict:
    f_n = abs(np.log(p)) / (2 * np.pi * DT) if p != 0 else None
    return {"kind": "complex" if p.imag > 0 else "real", "pole": [p.real, p.imag], "natural_frequency_hz": f_n,
            "nyquist": bool(p.imag == 0 and p.real < 0), "supported": supported}


MAIN = pair(27_000.0, 0.05)
FAINT = pair(150_000.0, 0.003)  # a lightly damped mode beyond the excitation's band


def artefact_model() -> tuple[DiscreteModel, list[dict]]:
    """The main mode, a real pole at −0.98 (Nyquist), an unsupported ζ = 0.003 mode, and a
    non-minimum-phase zero at 1.5."""
    poles = np.concatenate([MAIN, FAINT, [-0.98]])
    model = model_of(poles, np.array([1.5, -0.5]))
    modes = [mode(MAIN[0]), mode(FAINT[0], supported=False), mode(-0.98 + 0j, supported=False)]
    return model, modes


def test_only_supported_modes_are_cancelled_and_zeros_never_inverted():
    model, modes = artefact_model()
    support = ShotSupport(model, modes, supported_band_hz=(0.0, 40_000.0))
    design = design_compensation(support)
    dcm = design.dcm
    np.testing.assert_allclose(np.sort_complex(dcm.zeros), np.sort_complex(MAIN), atol=1e-12)
    reasons = {tuple(np.round(s["pole"], 6)): s["reason"] for s in dcm.design["skipped_poles"]}
    assert "Nyquist" in reasons[(-0.98, 0.0)]
    assert "outside the band the excitation supports" in reasons[tuple(np.round([FAINT[0].real, FAINT[0].imag], 6))]
    # the ratio rule uses the supported main mode: the ζ = 0.003 mode (slower) is not its basis
    assert dcm.design["slowest_response_time_samples"] == pytest.approx(response_times_samples(MAIN)[0])
    assert response_times_samples(FAINT)[0] > 2 * dcm.design["slowest_response_time_samples"]
    # stable; the non-minimum-phase zero (1.5) is neither inverted nor mirrored (1/1.5)
    assert np.all(np.abs(dcm.poles) < 1)
    for z in (1.5, 1 / 1.5, -0.5):
        assert np.min(np.abs(dcm.poles - z)) > 0.05
    assert dcm.design["nonminimum_phase_zeros"] == [[1.5, 0.0]] and dcm.design["zeros_inverted"] is False


def test_a_resonance_that_shapes_the_band_is_cancelled_though_beyond_it():
    """An all-pole model's resonance beyond the band (identify marks it `shapes_band`: its rise
    inside the band is measured, its place is not) is cancelled; a plain unsupported mode is not."""
    beyond = pair(50_000.0, 0.02)
    model = model_of(np.concatenate([beyond, FAINT]))
    shaped = {**mode(beyond[0], supported=False), "shapes_band": True}
    design = design_compensation(ShotSupport(model, [shaped, mode(FAINT[0], supported=False)],
                                             supported_band_hz=(0.0, 28_000.0)))
    np.testing.assert_allclose(np.sort_complex(design.dcm.zeros), np.sort_complex(beyond), atol=1e-12)
    skipped = design.dcm.design["skipped_poles"]
    assert len(skipped) == 1 and "outside the band" in skipped[0]["reason"]


def test_bare_model_still_refuses_artefacts_and_spare_pole_zero_pairs():
    """Without an identification: a negative real pole, a mode near Nyquist and a pole a zero
    nearly cancels (a spare pair of the fit) are left alone."""
    spare_pole, spare_zero = 0.99897, 0.99899
    near_nyquist = pair(450_000.0, 0.05)
    model = model_of(np.concatenate([MAIN, [-0.98, spare_pole], near_nyquist]), np.array([spare_zero]))
    choice = choose_poles(ShotSupport(model))
    np.testing.assert_allclose(np.sort_complex(choice.cancelled), np.sort_complex(MAIN), atol=1e-9)
    reasons = " | ".join(s["reason"] for s in choice.skipped)
    assert "Nyquist" in reasons and "within 20 % of Nyquist" in reasons and "spare pole-zero pair" in reasons
    with pytest.raises(AnalysisError, match="outside the unit circle"):
        choose_poles(ShotSupport(model_of(np.array([1.02, 0.5]))))


def test_an_asked_widening_is_reached_and_says_so():
    model = model_of(MAIN)
    design = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 60_000.0)), AnalysisOptions(dcm_widening=3.0))
    assert design.target_widening == 3.0 and design.widening_note is None
    assert design.compensated_fbsd_hz["5"] == pytest.approx(3.0 * fbsd_hz(model)["5"], rel=2e-3)
    assert design.reached_widening == pytest.approx(3.0, rel=2e-3)
    assert design.noise_gain <= design.options.dcm_noise_gain_limit
    # the figures travel with the DCM (its JSON) and in the results' "dcm" keys
    assert design.dcm.design["reached_widening"] == design.reached_widening
    assert set(design.to_dict()) >= {"target_widening", "reached_widening", "widening_note", "noise_gain",
                                     "noise_gain_limit", "band_limit_hz", "latency_s"}


def test_a_target_beyond_the_band_limit_is_not_reached_and_the_note_says_why():
    model = model_of(MAIN)
    design = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 36_000.0)), AnalysisOptions(dcm_widening=10))
    assert design.reached_widening < 10
    assert "±5 % up to 36 kHz, the top of the band the excitation supports" in design.widening_note
    assert "caps it" in design.widening_note
    # the band limit's own ±5 % edge is the top of the supported band: the compensated band
    # reaches it and not beyond (within 2 %: the designed poles mapped by exp(sT) pass a
    # little more than 1 there)
    assert 0.9 * 36_000.0 <= design.compensated_fbsd_hz["5"] <= 1.02 * 36_000.0
    # the ±10 % edge lies beyond the supported band: said to be the model's extrapolation
    assert design.compensated_fbsd_hz["10"] > 36_000.0
    beyond = [n for n in design.notes if "unsupported by the excitation" in n]
    assert len(beyond) == (2 if design.compensated_fbsd_hz["5"] > 36_000.0 else 1)
    assert "compensated ±10 % edge" in beyond[-1] and "supports up to 36 kHz" in beyond[-1]
    assert f"puts the edge at {design.compensated_fbsd_hz['10'] / 1e3:.3g} kHz" in beyond[-1]
    assert "model's extrapolation" in beyond[-1]


def test_the_noise_gain_limit_bounds_the_automatic_ratio():
    model = model_of(MAIN)
    support = ShotSupport(model)  # no band known: no band limit, the noise gain grows with r
    free = design_compensation(support, AnalysisOptions(dcm_widening=8, dcm_noise_gain_limit=math.inf))
    assert free.widening_note is None and free.noise_gain > 3.0
    bounded = design_compensation(support, AnalysisOptions(dcm_widening=8, dcm_noise_gain_limit=3.0))
    assert bounded.noise_gain <= 3.0 and bounded.noise_gain > 2.9  # at the limit, not far below it
    assert "noise gain limit 3" in bounded.widening_note
    assert bounded.reached_widening < free.reached_widening
    # an explicit ratio is designed as asked and flagged when it exceeds the limit
    asked = design_compensation(support, AnalysisOptions(dcm_ratio=free.dcm.design["ratio"], dcm_noise_gain_limit=3.0))
    assert asked.noise_gain_exceeded and "exceeds the limit" in asked.notes[-1]


def test_noise_gain_is_the_white_noise_rms_gain():
    """Measured on white noise through the designed DCM (an independent estimate)."""
    design = design_compensation(ShotSupport(model_of(MAIN), supported_band_hz=(0.0, 60_000.0)))
    x = np.random.default_rng(3).standard_normal(400_000)
    y = signal.lfilter(design.dcm.fir, [1.0], signal.sosfilt(design.dcm.sos(), x))  # the sections, then the band limit
    assert np.std(y[1000:]) / np.std(x) == pytest.approx(design.noise_gain, rel=0.01)


def test_band_limit_choice():
    model = model_of(MAIN)
    auto = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 50_000.0), response_band_top_hz=42_000.0))
    assert "noise" in auto.band_limit.reason and "±5 % up to 42 kHz" in auto.band_limit.reason
    # automatic: the low-pass alone passes the lower top (42 kHz) at −5 %: a 4th-order
    # Butterworth's magnitude, whose cut-off is then 42 / (1/0.95² − 1)^(1/8) kHz, a closed form
    taps = auto.dcm.fir
    _, h = signal.freqz(taps, [1.0], worN=[42e3], fs=1 / DT)
    assert auto.band_limit.cutoff_hz == pytest.approx(42e3 / (1 / 0.95**2 - 1) ** 0.125, rel=1e-9)
    assert abs(h[0]) == pytest.approx(0.95, abs=1e-3)
    asked = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 50_000.0)), AnalysisOptions(dcm_band_limit_hz=30e3))
    assert asked.band_limit.cutoff_hz == 30e3 and asked.dcm.design["band_limit"]["order"] == 4
    off = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 50_000.0)), AnalysisOptions(dcm_band_limit_hz=0))
    assert off.band_limit.cutoff_hz is None and off.dcm.order == 2 and off.dcm.fir is None
    # the band limit is a linear-phase FIR: symmetric taps (a delay of exactly half its length at
    # every frequency), unit DC gain, the Butterworth's magnitude: −3 dB at the cut-off and
    # within 2e-3 of 1/√(1 + (f/f_c)⁸) from DC to twice the cut-off
    taps = band_limit_fir(30e3, DT)
    np.testing.assert_allclose(taps, taps[::-1], atol=1e-15)
    assert taps.size % 2 == 1 and np.sum(taps) == pytest.approx(1.0, abs=1e-12)
    f = np.linspace(0.0, 60e3, 601)
    _, h = signal.freqz(taps, [1.0], worN=f, fs=1 / DT)
    np.testing.assert_allclose(np.abs(h), 1 / np.sqrt(1 + (f / 30e3) ** 8), atol=2e-3)
    _, gd = signal.group_delay((taps, [1.0]), w=f[1:200], fs=1 / DT)
    np.testing.assert_allclose(gd, (taps.size - 1) / 2, atol=1e-6)
    with pytest.raises(AnalysisError, match="below Nyquist"):
        design_compensation(ShotSupport(model), AnalysisOptions(sample_rate_hz=None, dcm_band_limit_hz=600e3))


def test_latency_lines_the_compensated_output_up_with_the_input():
    """A pulse through the exact model, delayed 2.4 samples on the way (a channel skew), then the
    DCM with its latency removed: the input comes back in place; the latency is the shift that
    minimises the mismatch (half a sample either way is worse)."""
    from hopkinson.analysis.dcm_stream import apply
    from hopkinson.analysis.resample import shift_samples
    from hopkinson.analysis.response import model_output

    model = model_of(MAIN)
    design = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 60_000.0), channel_delay_samples=2.4))
    t = np.arange(3000)
    pulse = np.exp(-0.5 * ((t - 1000) / 12.0) ** 2)  # Gaussian, σ = 12 µs: inside the compensated band
    measured = shift_samples(model_output(model, pulse), 2.4)

    def mismatch(extra_samples: float) -> float:
        out = shift_samples(apply(design.dcm, measured, align=True), -extra_samples)
        return float(np.sqrt(np.mean((out - pulse) ** 2)))

    assert mismatch(0.0) < 0.01
    assert mismatch(0.0) < mismatch(0.5) and mismatch(0.0) < mismatch(-0.5)
    assert design.dcm.latency_s == design.latency_s
    assert design.dcm.design["latency"]["channel_delay_s"] == pytest.approx(2.4e-6)


def test_dc_group_delay_closed_form_agrees_with_scipy():
    design = design_compensation(ShotSupport(model_of(MAIN), supported_band_hz=(0.0, 60_000.0)))
    _, numeric = signal.group_delay((design.dcm.b, design.dcm.a), w=[1e-5])
    assert design.dcm.group_delay_samples == pytest.approx(float(numeric[0]), rel=1e-4)


def test_compensated_fbsd_of_the_true_sensor_matches_the_prediction_for_an_exact_model():
    model = model_of(MAIN)
    design = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 60_000.0)))
    assert compensated_fbsd_hz(model, design.dcm)["5"] == pytest.approx(design.compensated_fbsd_hz["5"])


@pytest.mark.parametrize(("cutoff_hz", "dt"), [(400e3, 1e-6), (37e3, 4e-6), (8e3, 1e-6)])
def test_the_band_limit_passes_its_edge_at_95_percent_from_near_nyquist_to_far_below(cutoff_hz, dt):
    """The ±5 % edge of the band limit, where the design puts the top of the supported band,
    against the closed form edge = f_c·(1/0.95² − 1)^(1/8): at 0.8 × Nyquist (the cap; 15 taps
    left it at 0.947 until MIN_BAND_LIMIT_TAPS), at 0.25 MS/s and at 1/160 of the rate."""
    taps = band_limit_fir(cutoff_hz, dt)
    edge = cutoff_hz * (1 / 0.95**2 - 1) ** 0.125
    _, h = signal.freqz(taps, [1.0], worN=[0.0, edge], fs=1 / dt)
    assert abs(h[0]) == pytest.approx(1.0, abs=1e-12) and abs(h[1]) == pytest.approx(0.95, abs=1e-3)


def pulse_support(width_s: float, top_hz: float, peak: float = 1.0, bipolar: bool = False) -> ShotSupport:
    """The MAIN sensor (its exact model) with a noise-free half-sine pulse of `width_s` (a
    bipolar one: followed by an equal negative half-sine, as a bonded bar pulse) and a
    supported band up to `top_hz`."""
    from hopkinson.analysis.dcm_ratio import ShotPulse
    from hopkinson.analysis.records import Record
    from hopkinson.analysis.response import model_output

    t = np.arange(6000) * DT - 1e-3
    pulse = np.where((t >= 0) & (t <= width_s), peak * np.sin(np.pi * t / width_s), 0.0)
    if bipolar:
        pulse -= np.where((t > width_s) & (t <= 2 * width_s), peak * np.sin(np.pi * (t - width_s) / width_s), 0.0)
    model = model_of(MAIN)
    record = Record(DT, pulse, model_output(model, pulse))
    return ShotSupport(model, supported_band_hz=(0.0, top_hz), pulse=ShotPulse.of(record))


def true_peak_ratio(support: ShotSupport, dcm) -> float:
    """The pulse through the exact sensor and the DCM: the output's peak over the input's, each
    read as the largest value of its band-limited interpolation ×16 (scipy.signal.resample_poly),
    independently of ShotPulse.peak_ratios (which reads peaks by analysis.excitation's fit)."""
    from hopkinson.analysis.dcm_stream import apply
    from hopkinson.analysis.response import model_output

    u = support.pulse.reference_m_s2
    y = apply(dcm, model_output(support.model, u))
    return float(np.max(signal.resample_poly(y, 16, 1)) / np.max(signal.resample_poly(u, 16, 1)))


@pytest.mark.parametrize("bipolar", [False, True])
def test_the_ratio_is_sized_to_the_pulse_where_its_compensated_peak_settles(bipolar):
    """A 25 µs pulse (content past the 27 kHz resonance) on the exact sensor, the band supported
    to 150 kHz, no noise bound: the automatic r is where the compensated peak stops changing. The
    fastest design the sample rate allows (analysis.dcm_ratio.max_ratio) changes it by at most
    0.1 % more (PEAK_SETTLED 0.05 % and the bisection's step), a 1.3 times slower one by more
    than 0.05 %; the predicted residual is the true one (an independent simulation). With the
    default noise bound the ratio stops at the bound."""
    from hopkinson.analysis.dcm_ratio import PEAK_SETTLED, max_ratio

    support = pulse_support(25e-6, 150e3, bipolar=bipolar)
    free = AnalysisOptions(dcm_noise_gain_limit=math.inf)
    design = design_compensation(support, free)
    r = design.dcm.design["ratio"]
    assert design.ratio_choice.sized_to == "pulse" and not design.widening_short
    assert design.target_widening is None and "sized to the pulse" in design.widening_note
    settled = true_peak_ratio(support, design.dcm)
    fastest = AnalysisOptions(dcm_ratio=max_ratio(design.poles.cancelled, design.options.dcm_damping), dcm_noise_gain_limit=math.inf)
    widest = true_peak_ratio(support, design_compensation(support, fastest).dcm)
    narrower = true_peak_ratio(support, design_compensation(support, AnalysisOptions(dcm_ratio=r / 1.3)).dcm)
    assert abs(settled - widest) <= 2 * PEAK_SETTLED
    assert abs(narrower - widest) > PEAK_SETTLED
    assert design.to_dict()["predicted_peak_error_pct"] == pytest.approx(100 * (settled - 1), abs=0.02)
    bounded = design_compensation(support)
    assert bounded.noise_gain <= bounded.options.dcm_noise_gain_limit < design.noise_gain


def test_a_longer_pulse_gets_a_narrower_band_and_the_scale_does_not_matter():
    """Sized to the pulse, not fixed: a 150 µs pulse (its content below ~10 kHz) needs less than
    a 25 µs one, and the choice does not depend on the pulse's height."""
    short = design_compensation(pulse_support(25e-6, 150e3))
    long = design_compensation(pulse_support(150e-6, 150e3))
    assert long.reached_widening < 0.5 * short.reached_widening
    scaled = design_compensation(pulse_support(25e-6, 150e3, peak=3.7e5))
    assert scaled.dcm.design["ratio"] == pytest.approx(short.dcm.design["ratio"], rel=1e-9)


def test_a_band_that_cuts_the_pulse_caps_the_ratio_and_the_note_says_so():
    """Supported only to 30 kHz, while the 25 µs pulse reaches beyond: the band limit holds the
    compensated band at 30 kHz; the widest design it allows still changes the peak by more than
    1 %, and the note (a warning on the shot) says which cap cuts the pulse and by how much."""
    support = pulse_support(25e-6, 30e3)
    design = design_compensation(support)
    assert design.widening_short and design.ratio_choice.sized_to == "pulse"
    assert design.compensated_fbsd_hz["5"] <= 1.02 * 30e3
    assert "the band the shot supports (band limit: at" in design.widening_note
    assert "cuts the pulse's content" in design.widening_note
    residual = true_peak_ratio(support, design.dcm) - 1
    said = float(re.search(r"changes its peak by ([-+][0-9.]+) %", design.widening_note).group(1))
    assert abs(residual) > 0.01 and said == pytest.approx(100 * residual, abs=0.3)


def test_the_noise_gain_limit_caps_a_pulse_sized_ratio():
    support = pulse_support(25e-6, 150e3)
    free = design_compensation(support)
    capped = design_compensation(support, AnalysisOptions(dcm_noise_gain_limit=0.5 * free.noise_gain))
    assert capped.noise_gain <= 0.5 * free.noise_gain and capped.reached_widening < free.reached_widening
    assert capped.widening_short and "the noise gain limit" in capped.widening_note


def test_without_a_pulse_the_band_then_a_fallback_sizes_the_ratio():
    """No pulse, a supported band: the widest ±5 % band the band limit allows (within 1 %). No
    band either (a bare model): ×3 of the model's band, said so."""
    model = model_of(MAIN)
    band = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 40e3)))
    assert band.ratio_choice.sized_to == "band" and "no pulse to size it to" in band.widening_note
    widest = design_compensation(ShotSupport(model, supported_band_hz=(0.0, 40e3)), AnalysisOptions(dcm_ratio=400.0))
    assert band.compensated_fbsd_hz["5"] >= 0.99 * widest.compensated_fbsd_hz["5"]
    bare = design_compensation(ShotSupport(model))
    assert bare.ratio_choice.sized_to == "fallback" and bare.target_widening == 3.0
    assert bare.reached_widening == pytest.approx(3.0, rel=2e-3)
    assert "neither a pulse nor a supported band" in bare.widening_note

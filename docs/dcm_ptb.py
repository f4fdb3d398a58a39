"""Where the default DCM's compensated peak error on PTB's record comes from (issue 40 item 6):
for engineers changing the DCM design or the identification.

    .venv/bin/python docs/dcm_ptb.py

The record is read from the installed PyDynamic (the test extra), as the tests read it; it is
identified with the default options and the DCM designed and checked as `hopkinson dcm --model
--record` and every shot analysis do (analysis.compensation.compensate_shot). Then each
candidate cause of the compensated peak error is measured on its own, every peak read by
analysis.excitation.peak_estimate as the check reads it:

- the DCM's own change of the pulse's peak: the model's response to the reference, compensated
  (no model error enters), and its parts applied to the reference alone: the band limit's
  prototype (ideal, zero phase, by FFT), its FIR realisation, the model's zeros the DCM leaves
  (a unit-DC-gain FIR of them), the designed poles;
- the model's error: the DCM applied to the response less the model's response to the
  reference, at the compensated peak; and the model's DC gain against the sine calibration's
  lowest point and against the quasi-static gain in the main pulse's direction
  (analysis.static_gain) (the compensated record is divided by the model's DC gain);
- the reading: the largest sample against the fit, the latency ±1 sample, the reference's
  peak at 10 MS/s against the analysis rate's;
- DCM designs that remove parts of the DCM's own change, as prototypes (not the shipped design):
  the FIR stage made to realise the prototype for the whole chain model × DCM (the pole-zero
  part's remainder equalised), twice the taps, a 6th-order prototype with the same ±5 % edge.

Last line: one JSON object.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import signal

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hopkinson.analysis import dcm_design  # noqa: E402
from hopkinson.analysis.compensation import _pulse_of, check_compensation, compensate_shot, to_rate  # noqa: E402
from hopkinson.analysis.dcm_ratio import model_response  # noqa: E402
from hopkinson.analysis.dcm_stream import apply  # noqa: E402
from hopkinson.analysis.excitation import peak_estimate  # noqa: E402
from hopkinson.analysis.identify import identify  # noqa: E402
from hopkinson.analysis.options import AnalysisOptions  # noqa: E402
from hopkinson.analysis.resample import shift_samples  # noqa: E402
from hopkinson.analysis.response import frequency_response  # noqa: E402
from hopkinson.analysis.static_gain import static_gain  # noqa: E402
from tests.ptb_shock import ptb_record, ptb_sine  # noqa: E402


def fir_prototype(design, order: int, equalise: bool, taps_per_rate: float) -> np.ndarray:  # noqa: ANN001
    """The band limit's taps as dcm_design.band_limit_fir makes them, with the same ±5 % edge,
    of `order`, and (equalise) divided by the pole-zero part's remainder |model × core| / DC."""
    dt = design.model.sample_interval_s
    nyquist = 0.5 / dt
    edge = design.band_limit.cutoff_hz * dcm_design._edge_fraction(dcm_design.BAND_LIMIT_ORDER)
    cutoff = edge / dcm_design._edge_fraction(order)
    taps = min(max(2 * math.ceil(0.5 * taps_per_rate / (edge * dt)) + 1, 31), 1001)
    turn = min(4 * cutoff, nyquist)
    grid = np.unique(np.concatenate([np.linspace(0, turn, 81), np.linspace(turn, nyquist, 33)]))
    bands = np.repeat(grid, 2)[1:-1]
    desired = 1 / np.sqrt(1 + (bands / cutoff) ** (2 * order))
    if equalise:
        core = replace(design.dcm, fir=None)
        rest = np.abs(frequency_response(design.model, bands) * core.frequency_response(bands))
        desired = desired / np.clip(rest / abs(design.model.dc_gain * core.dc_gain), 0.5, 2.0)
    h = signal.firls(taps, bands, desired, fs=2 * nyquist)
    return h / np.sum(h)


def main() -> dict:
    record10 = ptb_record()
    ident = identify(record10)
    model = ident.model
    dt = model.sample_interval_s
    record, _ = to_rate(record10, 1 / dt)
    shot = compensate_shot(ident, record10, AnalysisOptions())
    design, dcm, gain = shot.design, shot.design.dcm, model.dc_gain
    window = _pulse_of(record).window
    response = _pulse_of(record).response
    reference = np.asarray(record.reference, dtype=float)
    peak = peak_estimate(reference[window])[0]

    def error(x: np.ndarray, where: slice | None = window) -> float:
        return 100 * (peak_estimate(x if where is None else x[where], peak)[0] - peak) / peak

    rows: dict[str, float] = {}
    check = check_compensation(record, model, dcm, ident.delay_samples)
    rows["check: compensated peak error"] = check.peak_error_pct[1]
    rows["check: RMS error over the pulse"] = check.rms_error_pct[1]
    predicted = shift_samples(model_response(model, reference), ident.delay_samples)
    rows["DCM's own (through the model)"] = error(apply(dcm, predicted, initial="steady", align=True) / gain)
    n = 1 << 16
    spectrum = np.fft.rfft(reference - np.median(reference[: window.start]), n)
    f = np.fft.rfftfreq(n, dt)
    prototype = 1 / np.sqrt(1 + (f / design.band_limit.cutoff_hz) ** (2 * dcm_design.BAND_LIMIT_ORDER))
    rows["  band limit's prototype (ideal, zero phase)"] = error(np.fft.irfft(spectrum * prototype, n)[: reference.size])
    fir = dcm.fir
    rows["  band limit's FIR"] = error(shift_samples(signal.lfilter(fir, [1.0], reference), -(fir.size - 1) / 2), None)
    left = np.real(np.poly(model.zeros)) if model.zeros.size else np.array([1.0])
    rows["  the model's zeros the DCM leaves"] = error(shift_samples(
        signal.lfilter(left / np.sum(left), [1.0], reference), -(left.size - 1) / 2), None)
    designed = np.real(np.poly(dcm.poles[np.abs(dcm.poles) > 0]))
    rows["  the designed poles"] = error(signal.lfilter([np.sum(designed)], designed, reference), None)
    residual = apply(dcm, response - predicted, initial="steady", align=True) / gain
    at = window.start + int(round(peak_estimate(
        apply(dcm, response, initial="steady", align=True)[window] / gain, peak)[1]))
    rows["model's error (DCM × residual at the peak)"] = 100 * residual[at] / peak
    rows["  model DC gain over the sine's lowest point, -1"] = 100 * (gain / ptb_sine().magnitude[0] - 1)
    static, _ = static_gain(ident, [])
    if static is not None:
        rows["  static gain (main direction) over the model DC gain, -1"] = 100 * (static.value / gain - 1)
        rows["  ... its standard uncertainty"] = 100 * (static.u or math.nan) / static.value
    compensated = apply(dcm, response, initial="steady", align=True) / gain
    rows["reading: the check read on largest samples"] = 100 * (
        np.max(compensated[window]) - np.max(reference[window])) / np.max(reference[window])
    for shift in (-1, 1):
        moved = replace(dcm, latency_samples=dcm.latency_samples + shift)
        rows[f"reading: latency {shift:+d} sample"] = check_compensation(record, model, moved,
                                                                         ident.delay_samples).peak_error_pct[1]
    rows["reading: reference peak at 1 MS/s over 10 MS/s, -1"] = 100 * (
        peak / peak_estimate(np.asarray(record10.reference))[0] - 1)
    rows["noise gain (limit 4)"] = dcm.noise_gain()
    for name, order, equalise, taps in (("equalised", 4, True, 4.0), ("equalised, 2x taps", 4, True, 8.0),
                                        ("equalised, 2x taps, 6th order", 6, True, 8.0)):
        taps_ = fir_prototype(design, order, equalise, taps)
        latency = dcm.latency_samples + (taps_.size - fir.size) / 2
        trial = replace(dcm, fir=taps_, latency_samples=latency)
        got = check_compensation(record, model, trial, ident.delay_samples)
        rows[f"prototype DCM, {name}: peak error"] = got.peak_error_pct[1]
        rows[f"prototype DCM, {name}: RMS error"] = got.rms_error_pct[1]
    for key, value in rows.items():
        print(f"{key:58s} {value:+8.3f}")
    return rows


if __name__ == "__main__":
    print(json.dumps({k: round(float(v), 4) for k, v in main().items()}))

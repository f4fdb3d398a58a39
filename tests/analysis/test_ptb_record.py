"""PTB's shock record and sine calibration are read from the installed PyDynamic as issue 17
describes them (the facts below are the files', not this project's)."""

from __future__ import annotations

import numpy as np

from tests.ptb_shock import SINE_FBSD_5_HZ, SINE_FBSD_10_HZ, ptb_record, ptb_sine


def test_the_shock_record_is_ten_megasamples_per_second_and_84_km_s2():
    rec = ptb_record()
    assert rec.n_samples == 18_000
    assert rec.sample_rate_hz == 10e6
    assert 84e3 < rec.reference.max() < 85e3  # m/s², from km/s²
    assert rec.response_unit == "pC"


def test_the_sine_calibration_spans_half_to_twenty_kilohertz_with_its_edges():
    sine = ptb_sine()
    assert sine.frequency_hz[0] == 500 and sine.frequency_hz[-1] == 20_000
    relative = sine.magnitude / sine.magnitude[0]
    # the first crossings of +5 % and +10 %, linearly interpolated between the points
    for level, edge_hz in ((1.05, SINE_FBSD_5_HZ), (1.10, SINE_FBSD_10_HZ)):
        k = int(np.argmax(relative >= level))
        f = np.interp(level, relative[k - 1:k + 1], sine.frequency_hz[k - 1:k + 1])
        assert abs(f - edge_hz) < 30
    assert np.all(sine.u_magnitude_rel <= 0.005) and np.all(sine.u_phase_deg <= 0.5)

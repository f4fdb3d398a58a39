"""analysis.input_terms: the candidate input terms of a record."""

from __future__ import annotations

import numpy as np

from hopkinson.analysis.input_terms import ONSET, input_terms


def _pulse(n: int = 600, start: int = 100, width: int = 60) -> np.ndarray:
    """A half-sine pulse (peak 1), normalised as input_terms takes it, with a little noise."""
    k = np.arange(n)
    u = np.where((k >= start) & (k < start + width), np.sin(np.pi * (k - start) / width), 0.0)
    return u + 1e-4 * np.random.default_rng(3).standard_normal(n)


def test_the_onset_window_is_the_same_for_two_spellings_of_one_sample_interval() -> None:
    """1 µs computed as 1e-8 × 100 or read back from a file (0.9999999999999972 µs): the same
    window and the same bumps (8 µs before the foot was 8 samples at one and 9 at the other, and
    a realistic shot was fitted at one and refused at the other)."""
    u = _pulse()
    busy = np.zeros(u.size, dtype=bool)
    busy[80:200] = True
    made = [input_terms(u, dt, 103, 1e-4, busy, 60e3, False) for dt in (1e-6, 0.9999999999999972e-6, 1.0000000000000243e-6)]
    assert made[0].onset is not None and ONSET in made[0].names
    for other in made[1:]:
        assert other.onset == made[0].onset and other.names == made[0].names
        np.testing.assert_allclose(other.signals, made[0].signals, rtol=0, atol=1e-9)
    first, stop = made[0].onset
    assert stop - first == 8 + 14 + 1  # 8 µs before the foot, 14 µs after it, and the foot

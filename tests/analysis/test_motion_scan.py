"""The motion scan (analysis.noise.first_motion) gives exactly what judging each tail of a
stretch with is_motion in turn gives — the literal scan, the definition — in time linear in the
stretch: the tails share their Welch segments, so no tail is transformed again, and is_motion is
called only where a tail is motion or within rounding of its threshold."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis import noise, record_preparation
from hopkinson.analysis.noise import COHERENCE_SEGMENT, first_motion, is_motion
from tests.ptb_shock import noisier, ptb_record

RATE_HZ = 1e6
STEP, TAIL = 64, 5 * COHERENCE_SEGMENT  # record_preparation's MOTION_STEP and MOTION_TAIL


def literal_scan(x: np.ndarray, y: np.ndarray, onsets: list[int], stop: int, rate_hz: float = RATE_HZ
                 ) -> tuple[int, float] | None:
    """is_motion on x[onset:stop], y[onset:stop] for each onset in turn: the first that is motion."""
    for onset in onsets:
        verdict, msc = is_motion(x[onset:stop], y[onset:stop], rate_hz)
        if verdict:
            return onset, msc
    return None


def scan_onsets(start: int, stop: int) -> list[int]:
    return [start, *range(start + STEP, stop - TAIL + 1, STEP)]


def stretch(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Two noisy channels sharing a motion (a few kHz) that starts somewhere, or nowhere, at a
    random strength: some stretches are plain noise, some motion from the start, some in between
    with the coherence near its threshold."""
    n = int(rng.integers(200, 3000))
    x, y = rng.standard_normal(n), rng.standard_normal(n)
    begins = int(rng.integers(0, n + n // 4))
    motion = np.sin(2 * np.pi * rng.uniform(2e3, 2e4) / RATE_HZ * np.arange(n)) * (np.arange(n) >= begins)
    x += rng.uniform(0.0, 1.5) * motion
    y += rng.uniform(0.0, 1.5) * motion
    start, stop = int(rng.integers(0, 100)), n - int(rng.integers(0, 40))
    return x, y, start, stop


def test_the_scan_finds_what_the_literal_scan_finds_to_the_last_bit() -> None:
    rng = np.random.default_rng(7)
    found = 0
    for _ in range(80):
        x, y, start, stop = stretch(rng)
        onsets = scan_onsets(start, stop)
        fast, literal = first_motion(x, y, RATE_HZ, onsets, stop), literal_scan(x, y, onsets, stop)
        assert fast == literal  # the same onset and the same coherence, bit for bit (or both None)
        found += literal is not None
    assert 10 < found < 70  # both outcomes were exercised


def test_onsets_off_the_shared_grid_are_judged_tail_by_tail() -> None:
    rng = np.random.default_rng(8)
    x, y, _, _ = stretch(rng)
    stop = x.size
    onsets = [0, 50, 130, 131, 700]  # not half a segment apart: no shared segments
    assert first_motion(x, y, RATE_HZ, onsets, stop) == literal_scan(x, y, [o for o in onsets if stop - o >= 160], stop)


def test_is_motion_is_called_only_where_a_tail_may_be_motion(monkeypatch) -> None:
    """A long stretch of noise: the literal scan judges 1 500 tails of up to 10⁵ samples each
    (quadratic), the scan judges none of them again (linear)."""
    calls: list[int] = []

    def counted(x: np.ndarray, y: np.ndarray, rate: float) -> tuple[bool, float]:
        calls.append(x.size)
        return is_motion(x, y, rate)

    monkeypatch.setattr(noise, "is_motion", counted)
    rng = np.random.default_rng(9)
    n = 100_000
    x, y = rng.standard_normal(n), rng.standard_normal(n)
    onsets = scan_onsets(0, n)
    assert len(onsets) > 1_500
    assert first_motion(x, y, RATE_HZ, onsets, n) is None
    assert calls == []
    motion = np.sin(0.05 * np.arange(n)) * (np.arange(n) >= 60_000)
    assert first_motion(x + motion, y + motion, RATE_HZ, onsets, n) is not None
    assert 1 <= len(calls) <= 3  # the tail found (and any within rounding of its threshold)


@pytest.mark.parametrize("record", [ptb_record, lambda: noisier(0.02, 5)], ids=["PTB", "PTB with 2 % noise"])
def test_the_noise_stage_decides_on_ptbs_record_as_the_literal_scan_does(monkeypatch, record) -> None:
    """PTB's record (the bar's motion after the pulse) and a noisier copy (four moving
    stretches): the motion found, its coherence, the stretches at rest, the noise measured
    there and the band it leaves are the literal scan's, bit for bit."""
    def literal(x, y, rate, onsets, stop):
        return literal_scan(x, y, [o for o in onsets if stop - o >= 2.5 * COHERENCE_SEGMENT], stop, rate)

    def prepared() -> record_preparation.Prepared:
        return record_preparation.prepare_record(record(), 1e6, 12, None, 32).prep

    fast = prepared()
    monkeypatch.setattr(record_preparation, "first_motion", literal)
    slow = prepared()
    assert fast.noise.motion and any(m["reason"] == "coherent" for m in fast.noise.motion)  # the bar's motion is found
    assert fast.noise.motion == slow.noise.motion and fast.noise.y_segments == slow.noise.y_segments and fast.activity.lead_in == slow.activity.lead_in
    assert fast.band == slow.band
    for name in ("var_u", "var_y", "draw_var_u", "draw_var_y", "bin_hz"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
